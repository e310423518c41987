// The isotope command end to end: help and exit codes, reports of generated shapes, and bad
// input that must fail with a message and leave no output file behind (docs/DESIGN.md, invariant 6).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "isotope/source.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace {

namespace fs = std::filesystem;

struct Result {
  int code = -1;
  std::string out, err;
};

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    root_ = fs::temp_directory_path() / ("isotope_cli_" + std::to_string(getpid()) + "_" + info->name());
    fs::remove_all(root_);
    fs::create_directories(root_ / "logs");
    fs::create_directories(work());
  }
  void TearDown() override {
    std::error_code ignored;
    fs::remove_all(root_, ignored);
  }

  fs::path work() const { return root_ / "work"; }
  std::string in_work(const std::string& name) const { return (work() / name).string(); }

  Result run(const std::string& args) {
    const fs::path out = root_ / "logs" / "stdout", err = root_ / "logs" / "stderr";
    const std::string cmd =
        quote(ISOTOPE_BINARY) + " " + args + " >" + quote(out.string()) + " 2>" + quote(err.string());
    const int status = std::system(cmd.c_str());
    Result r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
  }

  std::set<std::string> listing() const {
    std::set<std::string> names;
    for (const auto& e : fs::recursive_directory_iterator(work())) names.insert(e.path().string());
    return names;
  }

  // generate SHAPE into work/NAME; asserts success.
  std::string generate(const std::string& shape, int size, const std::string& name) {
    const std::string path = in_work(name);
    const Result r = run("generate " + shape + " --size " + std::to_string(size) + " -q -o " + quote(path));
    EXPECT_EQ(r.code, 0) << r.err;
    return path;
  }

  nlohmann::json extract_report(const std::string& input_and_options) {
    const std::string mesh = in_work("mesh.ply"), report = in_work("report.json");
    const Result r = run("extract " + input_and_options + " -q -o " + quote(mesh) + " --report " + quote(report));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(r.out.empty()) << "--quiet printed: " << r.out;
    EXPECT_TRUE(fs::exists(mesh));
    if (!fs::exists(report)) return nlohmann::json::object();
    return nlohmann::json::parse(slurp(report));
  }

  // Runs a failing extract; checks the exit code, the message and that no file appeared.
  void expect_failure(const std::string& args, int expected_code, const std::string& message_part = "") {
    const std::set<std::string> before = listing();
    const Result r = run(args);
    if (expected_code >= 0) {
      EXPECT_EQ(r.code, expected_code) << args << "\nstderr: " << r.err;
    } else {
      EXPECT_NE(r.code, 0) << args;
    }
    EXPECT_FALSE(r.err.empty()) << "no message on stderr for: " << args;
    if (expected_code == 1) {
      EXPECT_NE(r.err.find("isotope: error: "), std::string::npos) << r.err;
    }
    if (!message_part.empty()) {
      EXPECT_NE(r.err.find(message_part), std::string::npos) << r.err;
    }
    EXPECT_EQ(listing(), before) << "a file was left behind by: " << args;
  }

  // A command stopped by Ctrl-C while it works: whether it was seen at work, and its exit code (-1
  // when it did not exit).
  struct Interrupted {
    bool seen = false;
    int code = -1;
  };
  // Starts `isotope ARGS` (stdout, and stderr too with QUIET, to /dev/null; TMPDIR set where given),
  // polls SEEN every POLL_MS milliseconds, at most TRIES times, until it says the work began, then
  // sends SIGINT and waits for the process to end.
  Interrupted interrupt_at_work(const std::vector<std::string>& args, const std::function<bool()>& seen, int tries,
                                int poll_ms, bool quiet = false, const std::string& tmpdir = "") {
    std::vector<char*> argv{const_cast<char*>(ISOTOPE_BINARY)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    const pid_t pid = fork();
    if (pid < 0) return {};
    if (pid == 0) {
      const int null = open("/dev/null", O_WRONLY);
      dup2(null, STDOUT_FILENO);
      if (quiet) dup2(null, STDERR_FILENO);
      if (!tmpdir.empty()) setenv("TMPDIR", tmpdir.c_str(), 1);
      execv(ISOTOPE_BINARY, argv.data());
      _exit(127);
    }
    Interrupted r;
    for (int i = 0; i < tries && !(r.seen = seen()); ++i) usleep(static_cast<useconds_t>(poll_ms) * 1000);
    kill(pid, SIGINT);
    int status = 0;
    if (waitpid(pid, &status, 0) == pid && WIFEXITED(status)) r.code = WEXITSTATUS(status);
    return r;
  }

  // Whether a file under DIR (and its folders, with RECURSIVE) has a name that begins with PREFIX;
  // any regular file for an empty PREFIX. The tree may change while it is read.
  static bool file_under(const std::string& dir, const std::string& prefix, bool recursive) {
    std::error_code ec;
    const auto matches = [&](const fs::directory_entry& e) {
      return prefix.empty() ? e.is_regular_file(ec) : e.path().filename().string().rfind(prefix, 0) == 0;
    };
    if (recursive) {
      for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
        if (matches(*it)) return true;
    } else {
      for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
        if (matches(*it)) return true;
    }
    return false;
  }

  std::string outputs() const { return " -o " + quote(in_work("out.ply")) + " --report " + quote(in_work("out.json")); }

  // Another build of the command (PROGRAM) run with ARGS in ENVIRONMENT ("env NAME=VALUE ..."); its
  // exit code and stderr.
  Result run_program(const std::string& program, const std::string& environment, const std::string& args) {
    const std::string cmd = environment + " " + quote(program) + " " + args + " 2>" + quote(in_work("err.txt"));
    const int status = std::system(cmd.c_str());
    Result r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.err = slurp(in_work("err.txt"));
    fs::remove(in_work("err.txt"));
    return r;
  }

  fs::path root_;
};

const std::string kData = ISOTOPE_TEST_DATA;

TEST_F(Cli, HelpOfEveryCommandExitsZeroAndNamesItsOptions) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"--help", {"extract", "convert", "info", "verify", "generate", "sweep", "bench", "demo", "--version"}},
      {"bench --help",
       {"--quick", "--json", "--threads", "--dataset", "--data", "--work-dir", "--cache-mb", "--scale", "--scale-size",
        "--quiet"}},
      {"sweep --help",
       {"--iso", "--eps", "--delta", "--weight", "--csv", "--plot", "--threads", "--cache-mb", "--quiet"}},
      {"convert --help", {"--memory-mb", "--threads", "--zstd-level", "--quantize", "--dims", "--type", "--quiet"}},
      {"info --help", {"STORE", "--json"}},
      {"verify --help", {"STORE", "--threads", "--quiet"}},
      {"extract --help",
       {"--iso", "--eps", "--error", "--topology", "simplify", "--weight", "--delta", "--report", "--compare-full",
        "--dims", "--type", "--output", "--quiet"}},
      {"generate --help",
       {"--size", "--shift", "--seed", "--output", "--type", "uint16", "algebraic", "linked-tori", "nested-spheres",
        "noise"}},
      {"demo --help", {"--out", "--data"}},
  };
  for (const auto& [args, words] : cases) {
    const Result r = run(args);
    EXPECT_EQ(r.code, 0) << args;
    for (const std::string& w : words) EXPECT_NE(r.out.find(w), std::string::npos) << args << " lacks " << w;
  }
}

TEST_F(Cli, VersionExitsZero) {
  const Result r = run("--version");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("isotope"), std::string::npos);
}

TEST_F(Cli, UsageErrorsExitTwo) {
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run("frobnicate").code, 2);
  EXPECT_EQ(run("extract --bogus").code, 2);
  EXPECT_EQ(run("extract x.raw -o y.ply").code, 2);  // --iso missing
  EXPECT_EQ(run("extract x.raw --iso 0").code, 2);   // output missing
  EXPECT_EQ(run("extract x.raw --iso 0 --topology sometimes -o y.ply").code, 2);
  EXPECT_EQ(run("generate cube -o y.raw").code, 2);
}

TEST_F(Cli, GeneratedSphereExtractsAsOneClosedSphere) {
  const std::string vol = generate("sphere", 33, "s_33x33x33_float32.raw");
  const nlohmann::json r = extract_report(quote(vol) + " --iso 0");
  EXPECT_GT(r.value("triangles", 0), 0);
  EXPECT_GT(r.value("vertices", 0), 0);
  EXPECT_EQ(r.value("components", -1), 1);
  EXPECT_EQ(r.value("euler_characteristic", -1), 2);
  EXPECT_EQ(r.value("boundary_edges", -1), 0);
  EXPECT_EQ(r.value("nonmanifold_edges", -1), 0);
  EXPECT_TRUE(r.contains("seconds"));
  EXPECT_EQ(r.value("error", ""), "bound");
  EXPECT_EQ(r.value("topology", ""), "preserve");
}

TEST_F(Cli, GeneratedClosedShapesKeepTheirTopologyAtCoarseEps) {
  struct Shape {
    const char* name;
    int components, chi;
  };
  for (const Shape& s : {Shape{"torus", 1, 0}, Shape{"linked-tori", 2, 0}, Shape{"nested-spheres", 3, 6}}) {
    const std::string vol = generate(s.name, 33, std::string(s.name) + "_33x33x33_float32.raw");
    for (const char* eps : {"0", "0.05"}) {
      const nlohmann::json r = extract_report(quote(vol) + " --iso 0 --eps " + eps);
      EXPECT_GT(r.value("triangles", 0), 0) << s.name << " eps " << eps;
      EXPECT_EQ(r.value("components", -1), s.components) << s.name << " eps " << eps;
      EXPECT_EQ(r.value("euler_characteristic", -1), s.chi) << s.name << " eps " << eps;
      EXPECT_EQ(r.value("boundary_edges", -1), 0) << s.name << " eps " << eps;
      EXPECT_EQ(r.value("nonmanifold_edges", -1), 0) << s.name << " eps " << eps;
      // A raw input is marched as it is at eps 0; only a coarser surface builds the hierarchy.
      EXPECT_EQ(r["preprocess"].is_null(), std::string(eps) == "0") << s.name << " eps " << eps;
    }
  }
}

// The printed code of iso 0 is where the surface lies in the stored uint16 values.
TEST_F(Cli, GenerateUint16PrintsTheMappingAndItsIsoCodeFindsTheShape) {
  const std::string vol = in_work("s_17x17x17_uint16.raw");
  const Result r = run("generate sphere --size 17 --type uint16 -o " + quote(vol));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(fs::file_size(vol), 17u * 17u * 17u * 2u);
  EXPECT_NE(r.out.find("-> 0,"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("-> 65535"), std::string::npos) << r.out;
  const size_t at = r.out.find("iso 0 -> ");
  ASSERT_NE(at, std::string::npos) << r.out;
  const std::string iso = r.out.substr(at + 9, r.out.find('\n', at) - at - 9);
  const nlohmann::json report = extract_report(quote(vol) + " --iso " + iso);
  EXPECT_EQ(report.value("components", -1), 1);
  EXPECT_EQ(report.value("euler_characteristic", -1), 2);
}

TEST_F(Cli, GenerateUint8WritesOneBytePerNode) {
  const std::string vol = in_work("n_9x9x9_uint8.raw");
  ASSERT_EQ(run("generate noise --size 9 --type uint8 -q -o " + quote(vol)).code, 0);
  EXPECT_EQ(fs::file_size(vol), 729u);
}

TEST_F(Cli, GenerateTypeThatTheOutputCannotCarryIsAUsageError) {
  expect_failure("generate sphere --size 9 --type uint16 -o " + quote(in_work("s.h5")), 2, "float32");
  expect_failure("generate sphere --size 9 --type uint8 -o " + quote(in_work("s_9x9x9_uint16.raw")), 2, "uint16");
  expect_failure("generate sphere --size 9 -o " + quote(in_work("s_8x8x8_float32.raw")), 2, "8x8x8");
  expect_failure("generate sphere --size 9 --type int16 -o " + quote(in_work("s.raw")), 2);
}

TEST_F(Cli, GeneratedHdf5AndRawGiveTheSameMesh) {
  const std::string raw = generate("noise", 17, "n_17x17x17_float32.raw");
  const std::string h5 = generate("noise", 17, "n.h5");
  const nlohmann::json a = extract_report(quote(raw) + " --iso 0.1 --eps 0.02");
  const nlohmann::json b = extract_report(quote(h5 + ":/volume") + " --iso 0.1 --eps 0.02");
  EXPECT_GT(a.value("triangles", 0), 0);
  EXPECT_EQ(a.value("triangles", -1), b.value("triangles", -2));
  EXPECT_EQ(a.value("euler_characteristic", -1), b.value("euler_characteristic", -2));
}

TEST_F(Cli, RealHdf5AndRawGiveTheSameTriangleCount) {
  const nlohmann::json a = extract_report(quote(kData + "/neghip_66x66x66_uint8.raw") + " --iso 128.5");
  const nlohmann::json b = extract_report(quote(kData + "/neghip.h5:/volume") + " --iso 128.5");
  EXPECT_GT(a.value("triangles", 0), 0);
  EXPECT_EQ(a.value("triangles", -1), b.value("triangles", -2));
  EXPECT_EQ(a.value("components", -1), b.value("components", -2));
  EXPECT_EQ(a["data_dims"], b["data_dims"]);
}

TEST_F(Cli, TheSummaryLineGivesItsStageTimesToFourSignificantDigits) {
  // A small volume's extraction takes a few milliseconds: to the millisecond, one step of the last
  // digit was 15-20% of it (the benchmark reads these times).
  const Result out = run("extract " + quote(kData + "/neghip_66x66x66_uint8.raw") + " --iso 32.5 --eps 253 -o " +
                         quote(in_work("summary.ply")));
  ASSERT_EQ(out.code, 0) << out.err;
  for (const std::string stage : {"; preprocess ", ", extract "}) {
    const size_t at = out.out.find(stage);
    ASSERT_NE(at, std::string::npos) << out.out;
    const size_t begin = at + stage.size(), end = out.out.find(" s", begin);
    ASSERT_NE(end, std::string::npos) << out.out;
    const std::string number = out.out.substr(begin, end - begin);
    std::string digits;
    for (char c : number)
      if (c >= '0' && c <= '9') digits += c;
    digits.erase(0, digits.find_first_not_of('0'));  // leading zeros are not significant
    EXPECT_EQ(digits.size(), 4u) << stage << number << " in " << out.out;
  }
}

TEST_F(Cli, RawSizeNotMatchingDimsFailsAndWritesNothing) {
  const std::string vol = generate("sphere", 9, "plain.raw");
  expect_failure("extract " + quote(vol) + " --dims 9x9x10 --type float32 --iso 0" + outputs(), 1);
  expect_failure("extract " + quote(vol) + " --dims 9x9x8 --type float32 --iso 0" + outputs(), 1);
  expect_failure("extract " + quote(vol) + " --iso 0" + outputs(), 1);  // neither name nor --dims say
}

TEST_F(Cli, TruncatedRawFailsAndWritesNothing) {
  const std::string vol = generate("sphere", 9, "t_9x9x9_float32.raw");
  fs::resize_file(vol, fs::file_size(vol) - 6);
  expect_failure("extract " + quote(vol) + " --iso 0" + outputs(), 1);
}

TEST_F(Cli, MissingFileFailsAndWritesNothing) {
  expect_failure("extract " + quote(in_work("gone_8x8x8_uint8.raw")) + " --iso 0" + outputs(), 1);
  expect_failure("extract " + quote(in_work("gone.h5:/volume")) + " --iso 0" + outputs(), 1);
}

TEST_F(Cli, MissingHdf5DatasetFailsAndWritesNothing) {
  expect_failure("extract " + quote(kData + "/neghip.h5:/nope") + " --iso 128.5" + outputs(), 1, "nope");
}

TEST_F(Cli, NanInDataFailsAndWritesNothing) {
  std::vector<float> v(4 * 4 * 4, 1.0f);
  v[21] = std::numeric_limits<float>::quiet_NaN();
  const std::string vol = in_work("nan_4x4x4_float32.raw");
  {
    std::ofstream out(vol, std::ios::binary);
    out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(float)));
  }
  expect_failure("extract " + quote(vol) + " --iso 0.5" + outputs(), 1);
}

TEST_F(Cli, OutputIntoMissingDirectoryFailsAndWritesNothing) {
  const std::string vol = generate("sphere", 9, "s_9x9x9_float32.raw");
  expect_failure("extract " + quote(vol) + " --iso 0 -o " + quote(in_work("no/such/dir/m.ply")), 1);
  // A report that cannot be written must not leave the mesh behind either.
  expect_failure("extract " + quote(vol) + " --iso 0 -o " + quote(in_work("m.ply")) + " --report " +
                     quote(in_work("no/such/dir/r.json")),
                 1);
  expect_failure("generate sphere --size 9 -o " + quote(in_work("no/such/dir/s.raw")), 1);
}

// The output policy (AtomicFile) through the commands: an output that is the input, or the
// other output, is refused before any work, and the input is left as it was; a FIFO as output is
// refused and stays a FIFO (a device node is tested in OutputFiles.AtomicFileNeverReplacesADeviceNode,
// made there by mknod).
TEST_F(Cli, AnOutputThatIsTheInputOrTheOtherOutputIsRefusedAndNothingChanges) {
  const std::string vol = generate("sphere", 9, "s_9x9x9_float32.raw");
  const std::string bytes = slurp(vol);
  // -o names a mesh format by its extension: the volume itself is refused as a usage error, and a
  // link with a mesh's name that leads back to it as the input.
  expect_failure("extract " + quote(vol) + " --iso 0 -o " + quote(vol), 2, "unknown mesh format '.raw'");
  fs::create_symlink(vol, in_work("same.ply"));
  expect_failure("extract " + quote(vol) + " --iso 0 -o " + quote(in_work("same.ply")), 1, "is the same file as INPUT");
  expect_failure("convert " + quote(vol) + " " + quote(vol), 1, "is the same file as INPUT");
  fs::create_symlink(vol, in_work("link.raw"));
  expect_failure("convert " + quote(vol) + " " + quote(in_work("link.raw")), 1, "is the same file as INPUT");
  expect_failure("sweep " + quote(vol) + " --iso 0 --csv " + quote(vol), 1, "is the same file as INPUT");
  expect_failure(
      "extract " + quote(vol) + " --iso 0 -o " + quote(in_work("m.ply")) + " --report " + quote(in_work("m.ply")), 1,
      "is the same file as -o");
  EXPECT_EQ(slurp(vol), bytes);
  ASSERT_EQ(::mkfifo(in_work("pipe.ply").c_str(), 0644), 0);
  expect_failure("extract " + quote(vol) + " --iso 0 -o " + quote(in_work("pipe.ply")), 1, "is a FIFO");
  EXPECT_TRUE(fs::is_fifo(in_work("pipe.ply")));
}

// --parts DIR writes a folder (OutputFolder): a new, empty or earlier --parts folder is
// written; a folder holding anything isotope did not write, the input among them, is refused and
// left as it was, byte for byte; of an earlier output only the files its manifest lists go.
TEST_F(Cli, PartsFolderNeverDeletesWhatIsotopeDidNotWrite) {
  const std::string vol = generate("sphere", 17, "s_17x17x17_float32.raw");
  const std::string extract = "extract " + quote(vol) + " --iso 0 --eps 0.01 -q --parts ";
  auto snapshot = [&](const fs::path& dir) {
    std::map<std::string, std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(dir))
      files[fs::relative(e.path(), dir).string()] = e.is_regular_file() ? slurp(e.path()) : "(folder)";
    return files;
  };
  // A folder that holds the input and a subfolder of notes: refused, and left as it was.
  const fs::path p = work() / "p";
  fs::create_directories(p / "sub");
  fs::copy_file(vol, p / "s_17x17x17_float32.raw");
  std::ofstream(p / "sub" / "notes.txt") << "x\n";
  const auto before = snapshot(p);
  expect_failure(
      "extract " + quote((p / "s_17x17x17_float32.raw").string()) + " --iso 0 --eps 0.01 --parts " + quote(p.string()),
      1, "holds INPUT");
  EXPECT_EQ(snapshot(p), before);
  // The same folder with the input elsewhere: still not isotope's.
  expect_failure(extract + quote(p.string()), 1, "is a folder that isotope did not write");
  EXPECT_EQ(snapshot(p), before);
  // A new folder, then written again over itself: only its own files, the manifest listing them.
  const fs::path q = work() / "q";
  ASSERT_EQ(run(extract + quote(q.string())).code, 0);
  EXPECT_EQ(slurp(q / "isotope-manifest.txt"), "isotope output folder 1\npart-00000.vtp\nmesh.pvtp\n");
  const Result again = run(extract + quote(q.string() + "/"));
  ASSERT_EQ(again.code, 0) << again.err;
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(q)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"isotope-manifest.txt", "mesh.pvtp", "part-00000.vtp"}));
  // An earlier output with a file of the user's added: refused, nothing removed.
  std::ofstream(q / "mine.txt") << "mine\n";
  const auto with_mine = snapshot(q);
  expect_failure(extract + quote(q.string()), 1, "holds 'mine.txt', which isotope did not write");
  EXPECT_EQ(snapshot(q), with_mine);
  // A manifest that lists a path out of the folder is not isotope's: refused.
  fs::remove(q / "mine.txt");
  std::ofstream(q / "isotope-manifest.txt") << "isotope output folder 1\n../s_17x17x17_float32.raw\nmesh.pvtp\n";
  expect_failure(extract + quote(q.string()), 1, "is a folder that isotope did not write");
  EXPECT_TRUE(fs::exists(vol));
  // An empty folder is taken; a file in its place is refused.
  fs::create_directories(work() / "empty");
  ASSERT_EQ(run(extract + quote((work() / "empty").string())).code, 0);
  EXPECT_TRUE(fs::exists(work() / "empty" / "mesh.pvtp"));
  expect_failure(extract + quote(vol), 1, "not a folder");
}

// An isotope built without MPI, started by a launcher as one of several ranks (the variables Open
// MPI's and MPICH's launchers set): every rank refuses and says why, nothing is written; as the
// only rank, or without a launcher, it runs.
TEST_F(Cli, ABinaryWithoutMpiRefusesToRunAsOneOfSeveralRanks) {
  const std::string vol = generate("sphere", 9, "s_9x9x9_float32.raw");
  const std::string mesh = in_work("m.ply");
  auto run_as = [&](const std::string& environment) {
    return run_program(ISOTOPE_WITHOUT_MPI_BINARY, environment,
                       "extract " + quote(vol) + " --iso 0 -q -o " + quote(mesh));
  };
  Result r = run_as("env OMPI_COMM_WORLD_SIZE=3 OMPI_COMM_WORLD_RANK=0");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("isotope: error: started by an MPI launcher as rank 0 of 3, but this isotope was built "
                       "without MPI"),
            std::string::npos)
      << r.err;
  r = run_as("env OMPI_COMM_WORLD_SIZE=3 OMPI_COMM_WORLD_RANK=2");  // each rank says so: no rank 0 may speak
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("as rank 2 of 3, but this isotope was built without MPI"), std::string::npos) << r.err;
  r = run_as("env PMI_SIZE=2 PMI_RANK=0");  // MPICH's Hydra
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("of 2, but this isotope was built without MPI"), std::string::npos) << r.err;
  r = run_as("env PMIX_RANK=1");  // PMIx, how many not said
  EXPECT_EQ(r.code, 1);
  EXPECT_FALSE(fs::exists(mesh));
  r = run_as("env OMPI_COMM_WORLD_SIZE=1 OMPI_COMM_WORLD_RANK=0");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(mesh));
  fs::remove(mesh);
  r = run_as("env -u OMPI_COMM_WORLD_SIZE -u PMI_SIZE -u PMIX_RANK -u PMI_RANK -u OMPI_COMM_WORLD_RANK");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(mesh));
}

// What the dynamic loader maps when the command starts (ldd's way: the program itself does not run).
std::string loaded_at_start(const std::string& listing) {
  EXPECT_EQ(std::system(("LD_TRACE_LOADED_OBJECTS=1 " + quote(ISOTOPE_BINARY) + " > " + quote(listing)).c_str()), 0);
  std::string loaded = slurp(listing);
  fs::remove(listing);
  EXPECT_NE(loaded.find("libtbb"), std::string::npos) << loaded;  // the listing is what it claims to be
  return loaded;
}

// Where the system's static archives link, the command carries HDF5, libtiff with its codecs,
// zstd, xxHash and zlib in itself: the dynamic loader maps none of them at its start.
TEST_F(Cli, CommandLoadsNoLibraryItsArchivesHold) {
#ifndef ISOTOPE_COMMAND_ARCHIVES
  GTEST_SKIP() << "the command links the shared libraries here (ISOTOPE_ARCHIVE_LINK off, or an archive missing "
                  "or failing to link)";
#endif
  const std::string loaded = loaded_at_start(in_work("loaded.txt"));
  for (const char* library : {"libhdf5", "libtiff", "libwebp", "libsharpyuv", "libLerc", "libjbig", "libjpeg",
                              "libdeflate", "liblzma", "libzstd", "libxxhash", "libsz", "libaec", "libz."})
    EXPECT_EQ(loaded.find(library), std::string::npos) << library << " is loaded at the command's start:\n" << loaded;
}

// The libraries that only one command needs are loaded by that command alone (cpp-httplib with
// OpenSSL by serve, PLplot by plots, MPI under an MPI launcher): every other command starts
// without them. A copy of the program with no modules beside it still extracts, and each command
// that needs a module says which one it cannot open, exit 1, and writes nothing.
TEST_F(Cli, LibrariesOfOneCommandAreLoadedByThatCommandAlone) {
  const std::string loaded = loaded_at_start(in_work("loaded.txt"));
  // (Not libssl by name: HDF5's shared library, where the command links that one, loads it too.)
  for (const char* library : {"libcpp-httplib", "libplplot", "libmpi"})
    EXPECT_EQ(loaded.find(library), std::string::npos) << library << " is loaded by every command:\n" << loaded;

  const std::string vol = generate("sphere", 9, "s_9x9x9_float32.raw");
  const std::string store = in_work("s.isotope");
  ASSERT_EQ(run("convert -q " + quote(vol) + " " + quote(store)).code, 0);
  // In the build tree, not the temp folder, which may be mounted noexec.
  const fs::path home = fs::path(ISOTOPE_TEST_BINARY_DIR) / ("alone_" + std::to_string(getpid()));
  struct Removed {
    fs::path path;
    ~Removed() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  } removed{home};
  const fs::path alone = home / "bin" / "isotope";
  fs::create_directories(alone.parent_path());
  fs::copy_file(ISOTOPE_BINARY, alone);
  auto run_alone = [&](const std::string& environment, const std::string& args) {
    // A bounded wait: a serve that found its module would listen until stopped.
    return run_program(alone.string(), "timeout 60 " + environment, args);
  };
  const std::string mesh = in_work("m.ply");
  Result r = run_alone("", "extract " + quote(store) + " --iso 0 -q -o " + quote(mesh));
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(mesh));
  fs::remove(mesh);
  // As the program names it: from its resolved path (/proc/self/exe).
  const std::string missing = fs::weakly_canonical(alone.parent_path() / ISOTOPE_MODULE_DIR).string();
  r = run_alone("", "serve " + quote(store) + " --port 0 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("isotope: error: cannot open isotope's module " + missing + "/isotope-serve.so: "),
            std::string::npos)
      << r.err;
  const std::string png = in_work("p.png");
  r = run_alone("", "sweep " + quote(store) + " --iso 0 --eps 0 --plot " + quote(png) + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("cannot open isotope's module " + missing + "/isotope-plot.so: "), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(png));
#ifdef ISOTOPE_HAVE_MPI  // under an MPI launcher, where this isotope was built with MPI
  r = run_alone("env OMPI_COMM_WORLD_SIZE=2 OMPI_COMM_WORLD_RANK=0",
                "extract " + quote(store) + " --iso 0 -q -o " + quote(mesh));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("cannot open isotope's module " + missing + "/isotope-mpi.so: "), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(mesh));
#endif
}

// A full disk, stood in for by a file size limit (ulimit -f: writes past it fail with EFBIG, as
// they fail with ENOSPC on a full disk; the command's main() ignores SIGXFSZ): a clear message, exit 1,
// no temporary left, and outputs that existed keep their bytes, the mesh and the report alike
// (both are finished before either is renamed, as `isotope extract` does), on 1 and 2 threads.
TEST_F(Cli, AFullDiskFailsWithAMessageAndLeavesEveryOutputAsItWas) {
  const std::string vol = generate("sphere", 65, "s_65x65x65_float32.raw");
  const std::string mesh = in_work("m.ply"), report = in_work("r.json"), store = in_work("s.isotope");
  {
    std::ofstream(mesh) << "old mesh";
    std::ofstream(report) << "old report";
  }
  const std::string limit = "ulimit -f 16; ";  // 16 KiB: the mesh is about 400 KiB, the store 180 KiB
  for (const std::string threads : {"1", "2"}) {
    const std::set<std::string> before = listing();
    const std::string cmd = limit + quote(ISOTOPE_BINARY) + " extract " + quote(vol) + " --iso 0 --threads " + threads +
                            " -o " + quote(mesh) + " --report " + quote(report) + " 2>" + quote(in_work("err"));
    const int status = std::system(("bash -c " + quote(cmd)).c_str());
    ASSERT_TRUE(WIFEXITED(status)) << "killed by a signal";
    EXPECT_EQ(WEXITSTATUS(status), 1);
    const std::string err = slurp(in_work("err"));
    fs::remove(in_work("err"));
    EXPECT_NE(err.find("m.ply: write failed: File too large"), std::string::npos) << err;
    EXPECT_EQ(listing(), before);
    EXPECT_EQ(slurp(mesh), "old mesh");
    EXPECT_EQ(slurp(report), "old report");
  }
  // A store is appended past the page cache by a writer thread a MiB at a time: one smaller than
  // that (180 KB) meets the limit in its last write, one of 8.5 MB in the writer thread's.
  const std::string big = generate("sphere", 129, "s_129x129x129_float32.raw");
  for (const std::string& input : {vol, big}) {
    const std::string cmd = limit + quote(ISOTOPE_BINARY) + " convert " + quote(input) + " " + quote(store) + " -q 2>" +
                            quote(in_work("err"));
    const int status = std::system(("bash -c " + quote(cmd)).c_str());
    ASSERT_TRUE(WIFEXITED(status)) << input;
    EXPECT_EQ(WEXITSTATUS(status), 1) << input;
    EXPECT_NE(slurp(in_work("err")).find("s.isotope: write failed: File too large"), std::string::npos) << input;
    fs::remove(in_work("err"));
    EXPECT_FALSE(fs::exists(store));
  }
  // A mesh's large arrays go past the page cache where whole pages allow: the faces of this one
  // (2.2 MB) meet a limit of 1 MiB in such a write, on 2 threads.
  const std::set<std::string> before = listing();
  const std::string cmd = "ulimit -f 1024; " + quote(ISOTOPE_BINARY) + " extract " + quote(big) +
                          " --iso 0 --threads 2 -o " + quote(mesh) + " 2>" + quote(in_work("err"));
  const int status = std::system(("bash -c " + quote(cmd)).c_str());
  ASSERT_TRUE(WIFEXITED(status)) << "killed by a signal";
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_NE(slurp(in_work("err")).find("m.ply: write failed: File too large"), std::string::npos);
  fs::remove(in_work("err"));
  EXPECT_EQ(listing(), before);
  EXPECT_EQ(slurp(mesh), "old mesh");
  // A convert's hand-over of 103 MB (257^3) would go to scratch files beside the store, which
  // cannot take it under a limit of 32 MiB: one that fits the budget is kept in memory instead,
  // and the store (5 MB) is the one written without the limit; one beyond the budget (16 MB) has
  // no such way out: the same failure as the store's, the scratch files named.
  const std::string wide = in_work("s_257x257x257_uint8.raw");
  ASSERT_EQ(run("generate sphere --size 257 --type uint8 -q -o " + quote(wide)).code, 0);
  const std::string limited = "ulimit -f 32768; " + quote(ISOTOPE_BINARY) + " convert " + quote(wide) + " ";
  const std::string unlimited = in_work("unlimited.isotope");
  ASSERT_EQ(run("convert " + quote(wide) + " " + quote(unlimited) + " -q").code, 0);
  const std::set<std::string> before_convert = listing();
  const int status_fits = std::system(("bash -c " + quote(limited + quote(store) + " -q")).c_str());
  ASSERT_TRUE(WIFEXITED(status_fits)) << "killed by a signal";
  EXPECT_EQ(WEXITSTATUS(status_fits), 0);
  EXPECT_TRUE(slurp(store) == slurp(unlimited)) << "the store differs from the one written without the limit";
  fs::remove(store);
  const std::string beyond = limited + quote(store) + " --memory-mb 16 -q 2>" + quote(in_work("err"));
  const int converted = std::system(("bash -c " + quote(beyond)).c_str());
  ASSERT_TRUE(WIFEXITED(converted)) << "killed by a signal";
  EXPECT_EQ(WEXITSTATUS(converted), 1);
  const std::string err = slurp(in_work("err"));
  EXPECT_NE(err.find("cannot write scratch data in '" + work().string() + "': File too large"), std::string::npos)
      << err;
  fs::remove(in_work("err"));
  EXPECT_EQ(listing(), before_convert);
}

TEST_F(Cli, InvalidNumbersAreUsageErrors) {
  const std::string vol = generate("sphere", 9, "s_9x9x9_float32.raw");
  expect_failure("extract " + quote(vol) + " --iso 0 --eps -1" + outputs(), 2);
  expect_failure("extract " + quote(vol) + " --iso nan" + outputs(), 2);
  expect_failure("extract " + quote(vol) + " --iso inf" + outputs(), 2);
  expect_failure("extract " + quote(vol) + " --iso zero" + outputs(), 2);
  expect_failure("extract " + quote(vol) + " --iso 0 --dims 9x9" + outputs(), 2);
  expect_failure("generate sphere --size 1 -o " + quote(in_work("x.raw")), 2);
  expect_failure("generate sphere --size 9 -o " + quote(in_work("x.vtk")), 2);
  expect_failure("generate sphere --size 9 --shift 1,2,3 -o " + quote(in_work("x.raw")), 2);
  // Ranges named in the message, in numbers a person reads.
  for (const char* command : {"extract ", "sweep "}) {
    const Result r =
        run(command + quote(vol) + " --iso 0 --threads -1" + (std::string(command) == "sweep " ? "" : outputs()));
    EXPECT_EQ(r.code, 2) << command;
    EXPECT_NE(r.err.find("--threads"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("0 .. 4096 (0: all cores), got '-1'"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("e+308"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("1797693"), std::string::npos) << r.err;
  }
  expect_failure("convert " + quote(vol) + " " + quote(in_work("v.isotope")) + " --threads 5000", 2, "0 .. 4096");
  expect_failure("extract " + quote(vol) + " --iso 0 --max-triangles -1" + outputs(), 2, "--max-triangles");
  // A comparison tolerance too small to sample is refused before the work, not after it.
  expect_failure("extract " + quote(vol) + " --iso 0 --compare-full --compare-voxels 1e-300" + outputs(), 2,
                 "[0.0005, 1e6]");
}

TEST_F(Cli, ExtractAcceptsFractionsAndNegativeIsovalues) {
  const std::string vol = generate("algebraic", 17, "a_17x17x17_float32.raw");
  const nlohmann::json r = extract_report(quote(vol) + " --iso -0.25 --eps 1/16 --error surplus --topology paper");
  EXPECT_GT(r.value("triangles", 0), 0);
  EXPECT_DOUBLE_EQ(r.value("eps", -1.0), 0.0625);
  EXPECT_DOUBLE_EQ(r.value("iso", 0.0), -0.25);
  EXPECT_EQ(r.value("error", ""), "surplus");
  EXPECT_EQ(r.value("topology", ""), "paper");
}

// The store commands end to end: convert, info, verify, and extract giving the same mesh file
// from the store as from the raw input.
TEST_F(Cli, ConvertInfoVerifyAndExtractFromTheStore) {
  const std::string raw = kData + "/neghip_66x66x66_uint8.raw", store = in_work("neghip.isotope");
  const Result c = run("convert " + quote(raw) + " " + quote(store) + " --memory-mb 8 --threads 2");
  ASSERT_EQ(c.code, 0) << c.err;
  EXPECT_NE(c.out.find("66x66x66 uint8"), std::string::npos) << c.out;
  const Result info = run("info --json " + quote(store));
  ASSERT_EQ(info.code, 0) << info.err;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j["dims"], nlohmann::json({66, 66, 66}));
  EXPECT_EQ(j["type"], "uint8");
  EXPECT_LE(j["size_ratio"].get<double>(), 1.5);
  EXPECT_GT(j["critical_exact"]["cube"].get<int64_t>(), 0);
  EXPECT_EQ(run("info " + quote(store)).code, 0);
  const Result v = run("verify " + quote(store));
  EXPECT_EQ(v.code, 0) << v.err;
  EXPECT_NE(v.out.find("ok"), std::string::npos);
  for (const std::string eps : {"0", "8"}) {
    ASSERT_EQ(run("extract " + quote(raw) + " --iso 128.5 --eps " + eps + " -q -o " + quote(in_work("a.ply"))).code, 0);
    ASSERT_EQ(run("extract " + quote(store) + " --iso 128.5 --eps " + eps + " -q -o " + quote(in_work("b.ply"))).code,
              0);
    EXPECT_EQ(slurp(work() / "a.ply"), slurp(work() / "b.ply")) << "eps " << eps;
  }
}

TEST_F(Cli, CorruptStoreIsNamedByVerifyAndExtract) {
  const std::string store = in_work("bolt.isotope");
  ASSERT_EQ(run("convert -q " + quote(kData + "/bolt_70x123x66_uint8.raw") + " " + quote(store)).code, 0);
  std::string bytes = slurp(store);
  bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x40);
  std::ofstream(store, std::ios::binary | std::ios::trunc) << bytes;
  expect_failure("verify " + quote(store), 1, "brick ");
  // The flipped byte lies in a band-1 brick, which a coarse extraction reads (eps 0 marches band 0).
  expect_failure("extract " + quote(store) + " --iso 100 --eps 0.5 -o " + quote(in_work("m.ply")), 1, "brick ");
  std::ofstream(store, std::ios::binary | std::ios::trunc) << "not a store at all";
  expect_failure("verify " + quote(store), 1, "not an isotope store");
  expect_failure("info " + quote(store), 1, "not an isotope store");
}

TEST_F(Cli, ConvertFailuresLeaveNothing) {
  const std::string bolt = quote(kData + "/bolt_70x123x66_uint8.raw");
  expect_failure("convert " + quote(in_work("missing_9x9x9_uint8.raw")) + " " + quote(in_work("o.isotope")), 1);
  expect_failure("convert " + bolt + " " + quote(in_work("no/such/dir/o.isotope")), 1, "does not exist");
  expect_failure("convert " + bolt + " " + quote(in_work("o.isotope")) + " --quantize 8", 2, "integer");
  expect_failure("convert " + bolt + " " + quote(in_work("o.isotope")) + " --quantize 12", 2);
  expect_failure("convert " + bolt + " " + quote(in_work("o.isotope")) + " --zstd-level 30", 2);
  expect_failure("convert " + bolt, 2);
  expect_failure("verify " + quote(in_work("nothing.isotope")), 1);
}

// Ctrl-C during a convert: exit 1, "interrupted", no store and no temporary left.
// The signal comes once the convert has its temporary output open (the store being written):
// not a guess at how long it takes. A 225^3 volume converts in about a second on one thread, and
// the poll sees the temporary file within a millisecond of its creation.
// A triangle budget preserve cannot meet: refused with a hint; simplify without --delta chooses
// delta and eps, and the report says which and what was dropped; with --delta, delta is the user's.
TEST_F(Cli, SimplifyBudgetChoosesDeltaAndSaysSo) {
  const std::string raw = kData + "/hydrogen_64x64x64_float32.raw";
  const Result refused =
      run("extract " + quote(raw) + " --iso 0.001 --max-triangles 12000 -q -o " + quote(in_work("p.ply")));
  EXPECT_EQ(refused.code, 1);
  EXPECT_NE(refused.err.find("simplify with a budget and no delta"), std::string::npos) << refused.err;
  const nlohmann::json r = extract_report(quote(raw) + " --iso 0.001 --max-triangles 12000 --topology simplify");
  ASSERT_TRUE(r.contains("chosen_delta")) << r.dump();
  EXPECT_LE(r["triangles"].get<int64_t>(), 12000);
  EXPECT_GT(r["chosen_delta"].get<double>(), 0);
  EXPECT_GT(r["tets_dropped"].get<int64_t>(), 0);
  EXPECT_LE(r["delta_floor_triangles"].get<int64_t>(), 6000);
  const nlohmann::json given =
      extract_report(quote(raw) + " --iso 0.001 --max-triangles 12000 --topology simplify --delta 1");
  EXPECT_FALSE(given.contains("chosen_delta")) << "a delta given is used as it is";
}

// Ctrl-C while a one-shot extraction writes its volume's hierarchy store (in a folder of its own
// in TMPDIR) ends the command at once, with that folder removed.
TEST_F(Cli, InterruptedHierarchyStoreLeavesNothing) {
  const std::string vol = generate("noise", 225, "n_225x225x225_float32.raw");
  const std::string tmp = in_work("tmp");
  fs::create_directory(tmp);
  const Interrupted r = interrupt_at_work(
      {"extract", vol, "--iso", "0.2", "--eps", "0.01", "-o", in_work("n.ply"), "--threads", "1"},
      [&] { return file_under(tmp, ".hierarchy.isotope.tmp.", true); }, 20000, 1, false, tmp);  // at most 20 s
  EXPECT_TRUE(r.seen) << "the extraction never began its hierarchy's store";
  ASSERT_GE(r.code, 0) << "the extraction did not exit";
  EXPECT_EQ(r.code, 128 + SIGINT) << "the extraction finished before the signal, or failed otherwise";
  std::string left;
  for (const auto& e : fs::recursive_directory_iterator(tmp)) left += " " + e.path().string();
  EXPECT_EQ(left, "");
  EXPECT_FALSE(fs::exists(in_work("n.ply")));
}

TEST_F(Cli, InterruptedConvertLeavesNothing) {
  const std::string vol = generate("noise", 225, "n_225x225x225_float32.raw");
  const std::set<std::string> before = listing();
  const Interrupted r = interrupt_at_work(
      {"convert", vol, in_work("n.isotope"), "--threads", "1"},
      [&] { return file_under(work(), ".n.isotope.tmp.", false); }, 20000,
      1);  // at most 20 s
  EXPECT_TRUE(r.seen) << "the convert never opened its temporary output";
  ASSERT_GE(r.code, 0) << "the convert did not exit";
  EXPECT_EQ(r.code, 1) << "the convert finished before the signal, or failed otherwise";
  EXPECT_EQ(listing(), before);
}

}  // namespace

// Paged extraction: the same file for every thread count and cache budget (from one brick to
// the whole store), and the report says what was read.
TEST_F(Cli, StoreExtractIsTheSameFileForAnyThreadsAndCache) {
  const std::string store = in_work("bolt.isotope");
  ASSERT_EQ(run("convert -q " + quote(kData + "/bolt_70x123x66_uint8.raw") + " " + quote(store)).code, 0);
  // The full matrix (threads 1/2/4/8, budgets from 1 byte) runs in test_paged_extract; here the
  // command line, with a budget below one brick and one above the store.
  for (const std::string opts : {"--eps 0", "--eps 6 --focus 30,60,30 --radius 20", "--max-triangles 20000"}) {
    std::string first;
    for (int threads : {1, 2, 8}) {
      uint64_t bytes_read[2] = {};  // with the budget below one brick, and above the store
      for (int cache_mb : {1, 4096}) {
        const std::string what =
            opts + " --threads " + std::to_string(threads) + " --cache-mb " + std::to_string(cache_mb);
        const nlohmann::json r = extract_report(quote(store) + " --iso 100 " + what);
        ASSERT_FALSE(r.empty()) << what;
        EXPECT_EQ(r["threads"].get<int>(), threads) << what;
        EXPECT_GT(r["bricks_read"].get<int64_t>(), 0) << what;
        EXPECT_GT(r["cache_hits"].get<int64_t>(), 0) << what;  // the traversal comes back to the bricks it read
        EXPECT_GT(r["peak_rss_mb"].get<double>(), 1.0) << what;
        bytes_read[cache_mb == 4096] = r["bytes_read"].get<uint64_t>();
        const std::string mesh = slurp(work() / "mesh.ply");
        if (first.empty()) first = mesh;
        EXPECT_TRUE(mesh == first) << what << ": a different mesh file";
      }
      // A cache that holds the store reads each brick's sections once at most: never more than the
      // file. One below a brick evicts and reads again (bolt: 1.6 to 26 times as much), so the
      // budget is in effect and the mesh above does not depend on it.
      const std::string what = opts + " --threads " + std::to_string(threads);
      EXPECT_GT(bytes_read[1], 0u) << what;
      EXPECT_LE(bytes_read[1], fs::file_size(store)) << what;
      EXPECT_GT(bytes_read[0], bytes_read[1]) << what << ": --cache-mb 1 read no more than --cache-mb 4096";
    }
  }
}

// The report says whether a store's reads waited for the disk: none for a store the page cache
// holds whole (and no read-ahead hint, each a system call for nothing), some once it is dropped
// from the page cache (and hints ahead of the eps-0 march). Each half needs what it says of the
// page cache, and is skipped, saying so, where the file system does not do it.
TEST_F(Cli, ReportSaysWhetherAStoresReadsWaitedForTheDisk) {
  const std::string raw = in_work("noise_65x65x65_float32.raw"), store = in_work("noise.isotope");
  ASSERT_EQ(run("generate noise --seed 21 -q -o " + quote(raw)).code, 0);
  ASSERT_EQ(run("convert -q --brick-bits 3 " + quote(raw) + " " + quote(store)).code, 0);
  isotope::testing::read_into_page_cache(store);
  // Byte 1024: the first brick's, past the header (docs/FORMAT.md).
  if (isotope::testing::page_cached(store, 1024) != 1)
    GTEST_SKIP() << "the file system refuses RWF_NOWAIT, or does not keep " << store << " in the page cache";
  // The warm half, up to three tries, each from a store read whole into the page cache again:
  // once, in a CI run under ASan+UBSan with another test beside it, one read of the warm store
  // waited (a page of it dropped under memory pressure, as far as can be told). A try in which a
  // read waited is taken again; a reader that always waits, or says so of reads that did not,
  // fails all three. Two threads: on many, every slab could begin before a read waited, and find
  // the bricks it would have asked for read by then.
  nlohmann::json warm;
  for (int tries = 0; tries < 3; ++tries) {
    if (!isotope::testing::read_into_page_cache(store)) continue;
    warm = extract_report(quote(store) + " --iso 0 --threads 2");
    ASSERT_TRUE(warm.contains("cache")) << warm;
    if (warm["cache"]["read_waits"].get<int64_t>() == 0) break;
  }
  if (warm.empty()) GTEST_SKIP() << "the page cache did not keep " << store << " whole in three tries";
  EXPECT_GT(warm["bricks_read"].get<int64_t>(), 0);
  EXPECT_EQ(warm["cache"]["read_waits"].get<int64_t>(), 0) << warm["cache"];
  EXPECT_EQ(warm["cache"]["read_hints"].get<int64_t>(), 0) << warm["cache"];
  // The cold half, up to three tries, each from a store dropped again: once, in a CI run under
  // ASan+UBSan with another test beside it, every read of the dropped store found its bytes in the
  // page cache (the page checked below was dropped; what read the file back is not known). A try in
  // which no read waited is taken again; a reader that never waits, or never says so, fails all three.
  nlohmann::json cold;
  for (int tries = 0; tries < 3; ++tries) {
    ASSERT_TRUE(isotope::testing::drop_from_page_cache(store)) << store << ": fdatasync or posix_fadvise failed";
    if (isotope::testing::page_cached(store, 1024) != 0)
      GTEST_SKIP() << "the page cache keeps " << store << " when asked to drop it (a file system in memory?)";
    cold = extract_report(quote(store) + " --iso 0 --threads 2");
    ASSERT_TRUE(cold.contains("cache")) << cold;
    if (cold["cache"]["read_waits"].get<int64_t>() > 0) break;
  }
  EXPECT_GT(cold["cache"]["read_waits"].get<int64_t>(), 0) << cold["cache"];
  EXPECT_GT(cold["cache"]["read_hints"].get<int64_t>(), 0) << cold["cache"];
}

// A volume's coarse extraction pages its hierarchy from a store converted into the temporary
// directory: the report says what that store's cache read, beside the values the volume gave; at
// eps 0 (streamed) and with the hierarchy built in memory there is no cache to report.
TEST_F(Cli, ReportSaysWhatAVolumesHierarchyStoreRead) {
  const std::string vol = generate("noise", 65, "n_65x65x65_float32.raw");
  const uint64_t values = uint64_t{65} * 65 * 65 * sizeof(float);
  const std::string tmp = in_work("tmp");
  fs::create_directory(tmp);
  isotope::testing::TemporaryDirectoryIs in(tmp);
  const nlohmann::json coarse = extract_report(quote(vol) + " --iso 0.2 --eps 0.05");
  ASSERT_TRUE(coarse.contains("cache")) << coarse;
  EXPECT_EQ(coarse["bytes_read"].get<uint64_t>(), values);
  EXPECT_GT(coarse["bricks_read"].get<int64_t>(), 0);
  EXPECT_EQ(coarse["cache"]["budget_mb"].get<int64_t>(), 512);
  EXPECT_GT(coarse["cache"]["store_bytes"].get<uint64_t>(), 0u);
  EXPECT_GT(coarse["cache"]["bytes_read"].get<uint64_t>(), 0u);
  EXPECT_LE(coarse["cache"]["bytes_read"].get<uint64_t>(), coarse["cache"]["store_bytes"].get<uint64_t>());
  EXPECT_GT(coarse["cache"]["peak_decoded_mb"].get<double>(), 0.0);
  EXPECT_TRUE(fs::is_empty(tmp));
  EXPECT_GT(coarse["preprocess"]["critical_exact"]["cube"].get<int64_t>(), 0) << coarse;
  // Mode none: a store of the records' core alone, whose critical points nobody counted.
  const nlohmann::json none = extract_report(quote(vol) + " --iso 0.2 --eps 0.05 --topology none");
  EXPECT_TRUE(none["preprocess"]["critical_exact"].is_null()) << none;
  EXPECT_TRUE(none["preprocess"]["critical_paper"].is_null()) << none;
  EXPECT_LT(none["cache"]["store_bytes"].get<uint64_t>(), coarse["cache"]["store_bytes"].get<uint64_t>());
  const nlohmann::json full = extract_report(quote(vol) + " --iso 0.2");
  EXPECT_FALSE(full.contains("cache")) << full;
  EXPECT_EQ(full["bytes_read"].get<uint64_t>(), values);
  isotope::testing::TemporaryDirectoryIs nowhere(in_work("missing"));
  const nlohmann::json in_memory = extract_report(quote(vol) + " --iso 0.2 --eps 0.05");
  EXPECT_FALSE(in_memory.contains("cache")) << in_memory;
  EXPECT_EQ(in_memory["bytes_read"].get<uint64_t>(), values);
  EXPECT_EQ(in_memory["triangles"], coarse["triangles"]);
  EXPECT_EQ(in_memory["preprocess"]["critical_exact"], coarse["preprocess"]["critical_exact"]);
  const nlohmann::json none_in_memory = extract_report(quote(vol) + " --iso 0.2 --eps 0.05 --topology none");
  EXPECT_TRUE(none_in_memory["preprocess"]["critical_exact"].is_null()) << none_in_memory;
  EXPECT_EQ(none_in_memory["triangles"], none["triangles"]);
}

TEST_F(Cli, TriangleBudgetPicksTheFinestEpsWithinIt) {
  const std::string store = in_work("neghip.isotope");
  ASSERT_EQ(run("convert -q " + quote(kData + "/neghip_66x66x66_uint8.raw") + " " + quote(store)).code, 0);
  const nlohmann::json full = extract_report(quote(store) + " --iso 64");
  // One below full resolution: the finest step that fits refines some of the diamonds of error 0
  // (eps 0 and some tie classes), a cut, not the full-resolution mesh.
  const int64_t below_full = full["triangles"].get<int64_t>() - 1;
  for (int64_t budget : {int64_t{30000}, int64_t{60000}, below_full, full["triangles"].get<int64_t>() + 1}) {
    const nlohmann::json r = extract_report(quote(store) + " --iso 64 --max-triangles " + std::to_string(budget));
    const std::string chosen = slurp(work() / "mesh.ply");
    EXPECT_LE(r["triangles"].get<int64_t>(), budget);
    if (budget == below_full) {
      EXPECT_EQ(r["chosen_eps"].get<double>(), 0.0);
      EXPECT_GE(r["chosen_eps_ties"].get<int>(), 0);
    }
    EXPECT_EQ(r["max_triangles"].get<int64_t>(), budget);
    std::ostringstream eps, next;
    eps.precision(17), next.precision(17);
    eps << r["chosen_eps"].get<double>();
    next << r["next_eps"].get<double>();
    // The eps and tie classes reported give the same mesh by themselves; the next finer step
    // exceeds the budget.
    auto ties = [&](const char* key) {
      const int t = r[key].get<int>();
      return t >= 0 ? " --eps-ties " + std::to_string(t) : std::string();
    };
    extract_report(quote(store) + " --iso 64 --eps " + eps.str() + ties("chosen_eps_ties"));
    EXPECT_TRUE(slurp(work() / "mesh.ply") == chosen)
        << "budget " << budget << " eps " << eps.str() << ties("chosen_eps_ties");
    if (r["next_triangles"].get<int64_t>() == 0) {
      EXPECT_EQ(r["triangles"], full["triangles"]) << "no finer step left: the full-resolution mesh";
      continue;
    }
    const nlohmann::json finer = extract_report(quote(store) + " --iso 64 --eps " + next.str() + ties("next_eps_ties"));
    EXPECT_GT(finer["triangles"].get<int64_t>(), budget);
    EXPECT_EQ(finer["triangles"], r["next_triangles"]);
  }
  expect_failure("extract " + quote(store) + " --iso 64 --max-triangles 10" + outputs(), 1, "coarsest mesh");
}

TEST_F(Cli, FocusAndBudgetArgumentsAreChecked) {
  const std::string vol = quote(generate("sphere", 17, "s_17x17x17_float32.raw"));
  expect_failure("extract " + vol + " --iso 0 --focus 1,2 --radius 3" + outputs(), 2, "--focus");
  expect_failure("extract " + vol + " --iso 0 --focus 1,2,x --radius 3" + outputs(), 2, "--focus");
  expect_failure("extract " + vol + " --iso 0 --focus 1,2,3,4 --radius 3" + outputs(), 2, "--focus");
  expect_failure("extract " + vol + " --iso 0 --focus 1,2,3" + outputs(), 2, "radius");
  expect_failure("extract " + vol + " --iso 0 --radius 3" + outputs(), 2, "focus");
  expect_failure("extract " + vol + " --iso 0 --focus 0,0,0 --radius 0" + outputs(), 2, "--radius");
  expect_failure("extract " + vol + " --iso 0 --max-triangles -4" + outputs(), 2, "--max-triangles");
  expect_failure("extract " + vol + " --iso 0 --cache-mb 0" + outputs(), 2, "--cache-mb");
  const nlohmann::json r = extract_report(vol + " --iso 0 --eps 0.5 --focus 0,0,0.9 --radius 0.3");
  EXPECT_EQ(r["components"], 1);
  EXPECT_EQ(r["euler_characteristic"], 2);
  EXPECT_EQ(r["boundary_edges"], 0);
}

// Simplification from a store is the same file as from the raw volume (the weights are stored),
// delta 0 is preserve, and delta and weight are refused outside simplify mode.
TEST_F(Cli, SimplifyFromAStoreAndItsArguments) {
  const std::string raw = kData + "/neghip_66x66x66_uint8.raw", store = in_work("neghip.isotope");
  ASSERT_EQ(run("convert -q " + quote(raw) + " " + quote(store)).code, 0);
  const auto extract = [&](const std::string& input, const std::string& options, const std::string& name) {
    const Result r =
        run("extract " + quote(input) + " --iso 32.5 --eps 16 -q " + options + " -o " + quote(in_work(name)));
    EXPECT_EQ(r.code, 0) << options << "\n" << r.err;
    return slurp(work() / name);
  };
  const std::string preserve = extract(store, "", "preserve.ply");
  EXPECT_EQ(extract(store, "--topology simplify", "zero.ply"), preserve);
  EXPECT_EQ(extract(store, "--topology simplify --weight size --delta 0", "zero_size.ply"), preserve);
  for (const std::string w : {"interval --delta 8", "gradient --delta 40", "size --delta 20000"}) {
    const std::string from_store = extract(store, "--topology simplify --weight " + w, "s.ply");
    EXPECT_EQ(extract(raw, "--topology simplify --weight " + w, "r.ply"), from_store) << w;
    EXPECT_LT(from_store.size(), preserve.size()) << w;
  }
  // info names the largest weights; a delta above one gives the none mesh.
  const Result info = run("info --json " + quote(store));
  ASSERT_EQ(info.code, 0) << info.err;
  const double top = nlohmann::json::parse(info.out)["largest_weights"]["interval"].get<double>();
  EXPECT_GT(top, 0);
  const std::string none = extract(store, "--topology none", "none.ply");
  EXPECT_NE(none, preserve);
  EXPECT_EQ(extract(store, "--topology simplify --delta " + std::to_string(top * 1.01), "above.ply"), none);
  // --compare-full reads the store again for the full-resolution surface; bytes_read stays the
  // extraction's own.
  const nlohmann::json plain = extract_report(quote(store) + " --iso 32.5 --eps 16");
  const nlohmann::json compared = extract_report(quote(store) + " --iso 32.5 --eps 16 --compare-full");
  EXPECT_EQ(plain["bytes_read"], compared["bytes_read"]);
  EXPECT_GT(compared["compare_full"]["seconds"].get<double>(), 0);
  EXPECT_EQ(compared["compare_full"]["full"]["triangles"], extract_report(quote(store) + " --iso 32.5")["triangles"]);
  const nlohmann::json r =
      extract_report(quote(store) + " --iso 32.5 --eps 16 --topology simplify --weight gradient --delta 40");
  EXPECT_EQ(r["topology"], "simplify");
  EXPECT_EQ(r["weight"], "gradient");
  EXPECT_EQ(r["delta"], 40.0);
  EXPECT_GT(r["extract"]["tets_simplified"].get<int64_t>(), 0);
  const std::string vol = quote(raw);
  expect_failure("extract " + vol + " --iso 32.5 --delta 1" + outputs(), 2, "simplify");
  expect_failure("extract " + vol + " --iso 32.5 --topology none --weight size" + outputs(), 2, "simplify");
  expect_failure("extract " + vol + " --iso 32.5 --topology simplify --weight volume" + outputs(), 2, "--weight");
  expect_failure("extract " + vol + " --iso 32.5 --topology simplify --delta -1" + outputs(), 2, "--delta");
  expect_failure("extract " + vol + " --iso 32.5 --compare-full -o " + quote(in_work("x.ply")), 2, "--report");
}

// --report lists every component; --compare-full adds the full-resolution surface and names what
// the coarse mesh changed.
TEST_F(Cli, ReportPerComponentAndCompareFull) {
  const std::string tori = quote(generate("linked-tori", 33, "t_33x33x33_float32.raw"));
  nlohmann::json r = extract_report(tori + " --iso 0 --compare-full");
  ASSERT_EQ(r["per_component"].size(), 2u);
  int64_t triangles = 0;
  for (const auto& c : r["per_component"]) {
    EXPECT_EQ(c["genus"], 1);
    EXPECT_EQ(c["euler_characteristic"], 0);
    EXPECT_TRUE(c["closed"].get<bool>());
    EXPECT_GT(c["area"].get<double>(), 0);
    EXPECT_GT(c["volume"].get<double>(), 0);
    EXPECT_EQ(c["encloses"], "inside");
    for (int a = 0; a < 3; ++a) EXPECT_LT(c["bbox_min"][a].get<double>(), c["bbox_max"][a].get<double>());
    triangles += c["triangles"].get<int64_t>();
  }
  EXPECT_EQ(triangles, r["triangles"].get<int64_t>());
  // eps 0 is full resolution: nothing changed.
  EXPECT_EQ(r["compare_full"]["full"]["triangles"], r["triangles"]);
  EXPECT_EQ(r["compare_full"]["changes"].size(), 0u);
  EXPECT_EQ(r["compare_full"]["summary"]["unchanged"], 2);
  // Without topology control at a coarse eps the tori lose their handles or fall apart; the
  // comparison names it, and preserve changes nothing.
  r = extract_report(tori + " --iso 0 --eps 0.5 --topology none --compare-full");
  ASSERT_GT(r["compare_full"]["changes"].size(), 0u) << r["compare_full"].dump();
  EXPECT_EQ(r["compare_full"]["full"]["components"], 2);
  r = extract_report(tori + " --iso 0 --eps 0.5 --topology preserve --compare-full");
  EXPECT_EQ(r["compare_full"]["changes"].size(), 0u) << r["compare_full"].dump();
  // The matching tolerance is a number of voxel spacings (a raw file: spacing 1); the smaller it
  // is, the fewer of the coarse surface's samples find the full surface near them.
  const auto matched_share = [](const nlohmann::json& report) {
    const auto& m = report["compare_full"]["samples_matched"];
    return m["adaptive"].get<double>() / m["adaptive_of"].get<double>();
  };
  EXPECT_EQ(r["compare_full"]["match_tolerance"], 3.0);
  const nlohmann::json tight =
      extract_report(tori + " --iso 0 --eps 0.5 --topology preserve --compare-full --compare-voxels 0.1");
  EXPECT_NEAR(tight["compare_full"]["match_tolerance"].get<double>(), 0.1, 1e-12);
  EXPECT_LT(matched_share(tight), 0.5 * matched_share(r));
  expect_failure("extract " + tori + " --iso 0 --compare-full --compare-voxels 0" + outputs(), 2, "--compare-voxels");
  expect_failure("extract " + tori + " --iso 0 --compare-full --compare-voxels x" + outputs(), 2, "--compare-voxels");
  // The summary line on stdout.
  const Result out = run("extract " + tori + " --iso 0 --eps 0.5 --topology none --compare-full" + outputs());
  EXPECT_EQ(out.code, 0) << out.err;
  EXPECT_NE(out.out.find("against full resolution (2 components)"), std::string::npos) << out.out;
}

TEST_F(Cli, SweepTablesCsvAndPlot) {
  const std::string store = in_work("neghip.isotope");
  ASSERT_EQ(run("convert -q " + quote(kData + "/neghip_66x66x66_uint8.raw") + " " + quote(store)).code, 0);
  const std::string csv = in_work("sweep.csv"), png = in_work("sweep.png");
  const Result r = run("sweep " + quote(store) + " --iso 32.5 --eps 0,16,64 --delta 2,8 --csv " + quote(csv) +
                       " --plot " + quote(png));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("simplify delta=8"), std::string::npos) << r.out;
  std::istringstream lines(slurp(csv));
  std::string line;
  std::getline(lines, line);
  EXPECT_EQ(line, "mode,weight,delta,eps,triangles,components,euler_characteristic,seconds");
  std::vector<std::vector<std::string>> rows;
  while (std::getline(lines, line)) {
    std::vector<std::string> cells;
    std::istringstream in(line);
    for (std::string cell; std::getline(in, cell, ',');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 8u) << line;
    rows.push_back(cells);
  }
  ASSERT_EQ(rows.size(), 12u);  // 3 eps x (none, preserve, 2 deltas)
  // Every row is what extract gives for the same parameters.
  for (const auto& row : {rows[1], rows[5], rows[11]}) {
    std::string options = " --eps " + row[3] + " --topology " + row[0];
    if (row[0] == "simplify") options += " --weight " + row[1] + " --delta " + row[2];
    const nlohmann::json j = extract_report(quote(store) + " --iso 32.5" + options);
    EXPECT_EQ(std::to_string(j["triangles"].get<int64_t>()), row[4]) << options;
    EXPECT_EQ(std::to_string(j["components"].get<int64_t>()), row[5]) << options;
    EXPECT_EQ(std::to_string(j["euler_characteristic"].get<int64_t>()), row[6]) << options;
  }
  // At eps 0 every mode is the full-resolution mesh.
  EXPECT_EQ(rows[0][4], rows[3][4]);
  EXPECT_EQ(rows[0][4], rows[9][4]);
  const std::string bytes = slurp(png);
  ASSERT_GT(bytes.size(), 1000u);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  expect_failure("sweep " + quote(store) + " --iso 32.5 --eps 0,x", 2, "--eps");
  expect_failure("sweep " + quote(store) + " --iso 32.5 --delta -1", 2, "--delta");
  expect_failure("sweep " + quote(store) + " --iso 32.5 --weight volume", 2, "--weight");
  expect_failure("sweep " + quote(store) + " --iso 32.5 --plot " + quote(in_work("missing/p.png")), 1, "missing");
}

// isotope bench on two small datasets: every row is a ratio against the baseline of the same run,
// eps 0 gives the baseline's mesh, the coarse eps keeps at most 10% of it, a cold store is read
// and a warm one is not, scikit-image ran beside, and the paper's Table 1 is printed beside its
// numbers.
TEST_F(Cli, BenchTimesTheSuiteAgainstTheBaseline) {
  const std::string json = in_work("bench.json");
  const Result r = run("bench -q --quick --dataset algebraic65 --dataset neghip --threads 2 --data " + quote(kData) +
                       " --json " + quote(json) + " --work-dir " + quote(work().string()));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  for (const char* part :
       {"vs base", "Paper's Table 1", "VTK Flying Edges on the same array", "scikit-image", "Targets"})
    EXPECT_NE(r.out.find(part), std::string::npos) << part << "\n" << r.out;
  EXPECT_EQ(r.out.find("skipped"), std::string::npos) << r.out;
  EXPECT_EQ(listing(), std::set<std::string>{json}) << "the temporary stores must be gone";

  const nlohmann::json j = nlohmann::json::parse(slurp(json));
  ASSERT_EQ(j["datasets"].size(), 2u);
  std::map<std::string, nlohmann::json> dataset;
  for (const auto& d : j["datasets"]) dataset[d["name"]] = d;
  EXPECT_EQ(dataset["algebraic65"]["full_triangles"], 58772);  // ExactAtEpsZero's pinned count
  for (const auto& [name, d] : dataset) {
    EXPECT_GT(d["store_bytes"].get<uint64_t>(), 0u) << name;
    EXPECT_GT(d["convert_seconds"].get<double>(), 0) << name;
    EXPECT_GT(d["convert_peak_rss_mb"].get<double>(), 0) << name;
    EXPECT_GT(d["convert_ceiling_seconds"].get<double>(), 0) << name;
  }
  EXPECT_EQ(dataset["neghip"]["raw_bytes"], 66 * 66 * 66);
  const double disk_rate = j["machine"]["disk_read_bytes_per_second"].get<double>();
  EXPECT_GT(disk_rate, 0);
  EXPECT_GT(j["machine"]["disk_write_bytes_per_second"].get<double>(), 0);
  // The quiet rows' mesh files: a PLY holds 12 bytes per vertex and 13 per triangle past its header.
  // A GLB holds more: 12 bytes per vertex for the positions and as many for the normals.
  for (const auto& row : j["rows"]) {
    if (row["input"] == "one-shot -q ply" || row["input"] == "one-shot -q glb") {
      EXPECT_GT(row.value("bytes_written", uint64_t{0}), 13 * row["triangles"].get<uint64_t>()) << row;
    }
  }
  std::map<std::pair<std::string, int>, double> baseline;
  for (const auto& row : j["rows"])
    if (row["mode"] == "baseline") baseline[{row["dataset"], row["threads"].get<int>()}] = row["seconds"];
  ASSERT_EQ(baseline.size(), 4u) << "one and two threads per dataset";
  std::map<std::string, int> inputs;
  for (const auto& row : j["rows"]) {
    const std::string name = row["dataset"], input = row["input"];
    const auto full = dataset[name]["full_triangles"].get<int64_t>();
    const auto triangles = row["triangles"].get<int64_t>();
    const double seconds = row["seconds"];
    ++inputs[input];
    EXPECT_GE(row["runs"].get<int>(), input == "convert+extract" ? 1 : 3) << row;
    EXPECT_GT(row["peak_rss_bytes"].get<uint64_t>(), 0u) << row;
    EXPECT_NEAR(row["speedup_vs_baseline"].get<double>(), baseline.at({name, row["threads"].get<int>()}) / seconds,
                1e-9);
    EXPECT_NEAR(row["share_of_full"].get<double>(), static_cast<double>(triangles) / static_cast<double>(full), 1e-12);
    if (row["eps"] == 0) {
      EXPECT_EQ(triangles, full) << row;
    } else {
      EXPECT_EQ(row["eps"], dataset[name]["coarse_eps"]);
      if (row["mode"] == "none") {
        EXPECT_LE(triangles, full / 10) << row;
      }
      EXPECT_LT(triangles, full);
    }
    if (row["mode"] == "simplify") {
      const auto range = dataset[name]["value_range"];
      EXPECT_NEAR(row["delta"].get<double>(), 0.02 * (range[1].get<double>() - range[0].get<double>()), 1e-6);
    }
    // A cold store is read from the disk, no more than it holds; a warm cache, the raw array and
    // the hierarchy read nothing.
    EXPECT_EQ(row["bytes_read"].get<uint64_t>() > 0, input == "store-cold") << row;
    EXPECT_LE(row["bytes_read"].get<uint64_t>(), dataset[name]["store_bytes"].get<uint64_t>()) << row;
    // The processes are timed whole, and their extraction is part of that.
    if (input == "store-cold" || input.starts_with("one-shot") || input == "convert+extract") {
      EXPECT_GE(row["process_seconds"].get<double>(), seconds * 0.999) << row;
    } else {
      EXPECT_FALSE(row.contains("process_seconds")) << row;
    }
    // A cold row's floor: the same process with the store in the page cache, plus the bytes it
    // read at the disk's sequential rate measured in the run.
    if (input == "store-cold") {
      EXPECT_GT(row["warm_seconds"].get<double>(), 0) << row;
      EXPECT_NEAR(row["floor_seconds"].get<double>(),
                  row["warm_seconds"].get<double>() + row["bytes_read"].get<double>() / disk_rate, 1e-9)
          << row;
    } else {
      EXPECT_FALSE(row.contains("floor_seconds")) << row;
    }
  }
  // Per dataset: the baseline on 1 and 2 threads; six extraction cases in memory and from a warm
  // store; five from a cold one and mode none on one thread; one shot at eps 0 on 1 and 2 threads
  // and coarse; quiet, at eps 0 into PLY and into GLB on 1 and 2 threads; convert + extract. From
  // an HDF5 copy, eps 0 on 2 threads: neghip's (neghip.h5), none for the generated volume.
  EXPECT_EQ(inputs, (std::map<std::string, int>{{"raw", 4},
                                                {"memory", 12},
                                                {"store-warm", 12},
                                                {"store-cold", 12},
                                                {"one-shot", 6},
                                                {"one-shot -q ply", 4},
                                                {"one-shot -q glb", 4},
                                                {"one-shot h5", 1},
                                                {"convert+extract", 2}}));

  // scikit-image on the same files: the triangles of marching cubes, fewer than our tetrahedra's.
  ASSERT_EQ(j["peers"].size(), 2u);
  for (const auto& p : j["peers"]) {
    ASSERT_FALSE(p["skimage"].is_null()) << p;
    EXPECT_GT(p["skimage"]["triangles"].get<int64_t>(), 0) << p;
    EXPECT_LT(p["skimage"]["triangles"].get<int64_t>(), dataset[p["dataset"]]["full_triangles"].get<int64_t>()) << p;
    EXPECT_GT(p["skimage"]["load_and_march_seconds"].get<double>(), 0) << p;
    // The peers run under our extractions' allocator policy (isotope::keep_freed_memory).
    EXPECT_EQ(p["skimage"]["malloc_mmap_threshold"], std::to_string(isotope::kKeptBlockBytes)) << p;
    // VTK's Flying Edges on the same array, on one thread and on the two ours use: marching cubes
    // too, the same triangles as scikit-image where no value equals the isovalue (float data).
    const auto& fe = p["flying_edges"];
    ASSERT_FALSE(fe.is_null()) << p;
    EXPECT_EQ(fe["threads"], 2) << p;
    EXPECT_GT(fe["march_seconds_one_thread"].get<double>(), 0) << p;
    EXPECT_GT(fe["march_seconds_all_threads"].get<double>(), 0) << p;
    EXPECT_EQ(fe["malloc_mmap_threshold"], std::to_string(isotope::kKeptBlockBytes)) << p;
    if (p["dataset"] == "algebraic65") {
      EXPECT_EQ(fe["triangles"], p["skimage"]["triangles"]) << p;
    }
    EXPECT_NEAR(fe["triangles"].get<double>(), p["skimage"]["triangles"].get<double>(),
                0.01 * p["skimage"]["triangles"].get<double>())
        << p;
  }
  ASSERT_EQ(j["flying_edges"].size(), 2u);
  for (const auto& f : j["flying_edges"])
    EXPECT_EQ(f["ours"]["triangles"], dataset[f["dataset"]]["full_triangles"]) << f;

  // The targets that apply to small volumes, one verdict per row they judge.
  std::map<std::string, int> targets;
  for (const auto& t : j["targets"]) {
    ++targets[t["target"]];
    EXPECT_TRUE(t["met"].is_boolean()) << t;
    EXPECT_FALSE(t["value"].get<std::string>().empty()) << t;
  }
  EXPECT_EQ(targets["warm store within 1.25x of memory"], 12) << j["targets"];
  // Judged on runs taken in alternation, a ratio per pair, one set per case of each dataset.
  for (const auto& [name, d] : dataset) {
    ASSERT_EQ(d["warm_over_memory"].size(), 6u) << name;
    for (const auto& p : d["warm_over_memory"]) {
      EXPECT_GE(p["pairs"].get<int>(), 7) << p;
      EXPECT_GT(p["ratio"].get<double>(), 0) << p;
    }
  }
  for (const auto& t : j["targets"])
    if (t["target"] == "warm store within 1.25x of memory") {
      EXPECT_NE(t["value"].get<std::string>().find("pairs in alternation"), std::string::npos) << t;
    }
  EXPECT_EQ(targets["cold store within 1.5x of its floor"], 12) << "one per cold row";
  EXPECT_EQ(targets["eps 0 at least as fast as the baseline, same triangles"], 8) << j["targets"];
  EXPECT_EQ(targets["store no larger than format 2's"], 1) << "neghip has a format-2 size; algebraic 65^3 not";
  EXPECT_EQ(targets.count("convert >= 50% of the zstd ceiling"), 0u) << "only the volumes the speed targets name";

  // The paper's Table 1 beside ours: its numbers, our eps-0 count, fewer triangles as eps grows.
  const auto& t1 = j["paper_table1"];
  ASSERT_EQ(t1.size(), 5u);
  EXPECT_EQ(t1[0]["paper"]["without"], 59290);
  EXPECT_EQ(t1[4]["paper"]["with"], 3095);
  EXPECT_EQ(t1[0]["without"]["triangles"], 58772);
  for (size_t i = 1; i < t1.size(); ++i)
    for (const char* mode : {"without", "with"})
      EXPECT_LT(t1[i][mode]["triangles"].get<int64_t>(), t1[i - 1][mode]["triangles"].get<int64_t>());

  expect_failure("bench --dataset nope", 2, "algebraic257");
  expect_failure("bench --quick --json " + quote(in_work("missing/b.json")), 1, "missing");
  // A volume missing from --data is an error before anything runs, not a row left out.
  fs::create_directories(in_work("empty"));
  expect_failure("bench -q --dataset neghip --data " + quote(in_work("empty")), 1,
                 "neghip_66x66x66_uint8.raw: not found");
}

// isotope bench beside a reference executable (this one here, so the ratios are about 1): convert and
// the one-shot coarse surfaces of the dataset as whole processes in alternation, each ratio the
// reference's median over ours, each one a target with its verdict; convert on one thread against
// two beside them. A reference that is not an isotope executable is refused before anything runs.
TEST_F(Cli, BenchTimesConvertAndOneShotsBesideAReference) {
  const std::string json = in_work("bench.json");
  const Result r = run("bench -q --quick --dataset neghip --threads 2 --data " + quote(kData) + " --json " +
                       quote(json) + " --work-dir " + quote(work().string()) + " --reference " + quote(ISOTOPE_BINARY));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("the reference: " + std::string(ISOTOPE_BINARY) + " (isotope "), std::string::npos) << r.out;
  EXPECT_EQ(listing(), std::set<std::string>{json}) << "the outputs of the runs must be gone";
  const nlohmann::json j = nlohmann::json::parse(slurp(json));
  EXPECT_EQ(j["reference"]["executable"], ISOTOPE_BINARY);
  EXPECT_EQ(j["reference"]["version"], j["isotope_version"].get<std::string>().insert(0, "isotope "));
  ASSERT_EQ(j["datasets"].size(), 1u);
  const nlohmann::json& d = j["datasets"][0];
  std::vector<std::string> cases;
  for (const auto& v : d["against_reference"]) {
    cases.push_back(v["case"]);
    EXPECT_EQ(v["threads"], 2) << v;
    EXPECT_GE(v["rounds"], 3) << v;  // and until our runs add up to half a second
    EXPECT_LE(v["rounds"], 15) << v;
    EXPECT_GT(v["seconds"].get<double>(), 0) << v;
    EXPECT_GT(v["reference_seconds"].get<double>(), 0) << v;
    EXPECT_NEAR(v["ratio"].get<double>(), v["reference_seconds"].get<double>() / v["seconds"].get<double>(), 1e-12);
    EXPECT_GT(v["peak_rss_mb"].get<double>(), 1) << v;
    EXPECT_GT(v["reference_peak_rss_mb"].get<double>(), 1) << v;
  }
  EXPECT_EQ(cases, (std::vector<std::string>{"convert", "one-shot preserve", "one-shot none"}));
  const nlohmann::json& threads = d["convert_threads"];
  EXPECT_EQ(threads["threads"], 2);
  EXPECT_GT(threads["one_thread_seconds"].get<double>(), 0);
  EXPECT_NEAR(threads["ratio"].get<double>(),
              threads["one_thread_seconds"].get<double>() / threads["seconds"].get<double>(), 1e-12);
  // One target a case, met where the ratio is 3 or more.
  std::vector<double> ratios;
  for (const auto& t : j["targets"]) {
    const std::string what = t["target"];
    if (what.find("the reference") == std::string::npos) continue;
    EXPECT_EQ(t["dataset"], "neghip");
    const std::string value = t["value"];
    ratios.push_back(std::stod(value));
    EXPECT_EQ(t["met"].get<bool>(), ratios.back() >= 3) << t;
  }
  ASSERT_EQ(ratios.size(), 3u) << j["targets"];
  for (size_t i = 0; i < 3; ++i)
    EXPECT_NEAR(ratios[i], d["against_reference"][i]["ratio"].get<double>(), 0.01) << d["against_reference"][i];

  const std::string quick = "bench -q --quick --dataset neghip --data " + quote(kData) + " --reference ";
  expect_failure(quick + quote(in_work("nothing")), 2,
                 "--reference: '" + in_work("nothing") + "' is not an isotope executable (its --version did not run)");
  const std::string other = in_work("other");
  {
    std::ofstream script(other);
    script << "#!/bin/sh\necho 'other 1.0'\n";
  }
  fs::permissions(other, fs::perms::owner_all);
  expect_failure(quick + quote(other), 2, "is not an isotope executable (its --version printed 'other 1.0')");
}

// The large-volume row on a small volume: a coarse budget from the cold store (here the whole
// surface fits in it, so it is the eps-0 mesh) beside eps 0 in one process from the raw file,
// each a process timed whole, and the temporary files gone.
TEST_F(Cli, BenchScaleTimesTheBudgetBesideEpsZeroFromTheRawFile) {
  const std::string json = in_work("scale.json");
  const Result r =
      run("bench -q --scale --scale-size 65 --json " + quote(json) + " --work-dir " + quote(work().string()));
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* part : {"convert ", "extract ", "one-shot "})
    EXPECT_NE(r.out.find(part), std::string::npos) << part << "\n" << r.out;
  EXPECT_EQ(listing(), std::set<std::string>{json}) << "the volume and the store must be gone";
  const nlohmann::json j = nlohmann::json::parse(slurp(json));
  const auto& extract = j["extract"];
  const auto& full = j["one_shot_full"];
  EXPECT_GT(full["triangles"].get<int64_t>(), 0);
  EXPECT_EQ(extract["report"]["triangles"], full["triangles"]) << "a budget of 1 M holds the whole surface";
  EXPECT_EQ(extract["report"]["chosen_eps"], 0);
  for (const auto* run : {&extract, &full}) {
    EXPECT_GT((*run)["extract_seconds"].get<double>(), 0) << *run;
    EXPECT_GE((*run)["process_seconds"].get<double>(), (*run)["extract_seconds"].get<double>()) << *run;
    EXPECT_GT((*run)["peak_rss_mb"].get<double>(), 0) << *run;
  }
}

// Ctrl-C while bench converts its store (or, if that was quick, at its next run): exit 1, and
// neither the store nor its folder is left.
TEST_F(Cli, InterruptedBenchLeavesNothing) {
  // Wait for a file inside bench's folder: the store being written.
  const Interrupted r = interrupt_at_work(
      {"bench", "--dataset", "algebraic65", "--work-dir", work()}, [&] { return file_under(work(), "", true); }, 12000,
      10, true);
  ASSERT_TRUE(r.seen) << "no store appeared within 120 s";
  ASSERT_GE(r.code, 0) << "bench did not exit";
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(listing().empty());
}

// The public API as a contract, through <isotope/isotope.h> alone, as a host program uses it:
// every failure an isotope::Error of its kind, and a RunContext that changes how a call runs
// (threads, cancel, progress) but never the bytes it gives.
#include <gtest/gtest.h>
#include <oneapi/tbb/global_control.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "tests/support/temp_dir_test.h"
#include <isotope/isotope.h>

namespace isotope {
namespace {

static_assert(std::is_base_of_v<Error, OptionError> && std::is_base_of_v<Error, InvalidInput> &&
              std::is_base_of_v<Error, IoError> && std::is_base_of_v<Error, TriangleBudgetTooSmall> &&
              std::is_base_of_v<Error, ExtractionCancelled> && std::is_base_of_v<Error, DistributedError>);

// A sphere of radius 12 in a 33^3 array, values 0 at the surface, negative inside.
Volume sphere() {
  Volume v;
  v.dims = {33, 33, 33};
  v.values.resize(33 * 33 * 33);
  for (int64_t z = 0; z < 33; ++z)
    for (int64_t y = 0; y < 33; ++y)
      for (int64_t x = 0; x < 33; ++x)
        v.values[static_cast<size_t>(v.index(x, y, z))] = static_cast<float>(
            std::hypot(static_cast<double>(x) - 16, static_cast<double>(y) - 16, static_cast<double>(z) - 16) - 12);
  return v;
}

// What f throws, caught as an isotope::Error: its dynamic kind must be K, and its message `words`.
template <class K, class F>
void expect_error(const F& f, const std::string& words) {
  try {
    f();
    ADD_FAILURE() << "nothing thrown; expected: " << words;
  } catch (const Error& e) {
    EXPECT_NE(dynamic_cast<const K*>(&e), nullptr) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

class PublicApi : public testing::TempDirTest {};

TEST_F(PublicApi, EveryFailureIsAnIsotopeErrorOfItsKind) {
  const Volume v = sphere();
  ExtractOptions bad;
  bad.eps = -1;
  expect_error<OptionError>([&] { extract(v, bad); }, "eps must be");
  Volume thin = v;
  thin.dims = {1, 33, 33};
  expect_error<InvalidInput>([&] { extract(thin, {}); }, "dimensions");
  Volume nan = v;
  nan.values[100] = NAN;
  expect_error<InvalidInput>([&] { open_volume(nan); }, "not finite");
  VolumeSpec missing;
  missing.path = (dir_ / "missing_8x8x8_uint8.raw").string();
  expect_error<IoError>([&] { open_volume(missing); }, "missing_8x8x8");
  ExtractOptions tiny;
  tiny.max_triangles = 1;
  expect_error<TriangleBudgetTooSmall>([&] { extract(v, tiny); }, "triangles");
  const std::atomic<bool> stop{true};
  RunContext stopped;
  stopped.cancel = &stop;
  ExtractOptions coarse;
  coarse.eps = 0.5;
  expect_error<ExtractionCancelled>([&] { extract(v, coarse, stopped); }, "cancelled");
  expect_error<IoError>([&] { convert(v, (dir_ / "s.isotope").string(), {}, stopped); }, "interrupted");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "s.isotope"));
}

// A thread count out of range is refused by every call that takes a context, in the words the
// command's --threads and the Python module's threads= use (the CLI and Python suites compare them).
TEST_F(PublicApi, ARunContextOutOfRangeIsRefusedInTheFacesWords) {
  const Volume v = sphere();
  const Source source = open_volume(v);
  for (const int threads : {-1, kMaxThreads + 1}) {
    RunContext run;
    run.threads = threads;
    const std::string words = "threads must be an integer in 0 .. 4096 (0: all cores), got ";
    expect_error<OptionError>([&] { extract(v, {}, run); }, words);
    expect_error<OptionError>([&] { source.extract({}, run); }, words);
    expect_error<OptionError>([&] { source.prepare({}, run); }, words);
    expect_error<OptionError>([&] { convert(v, (dir_ / "t.isotope").string(), {}, run); }, words);
    try {
      run.validate();
      ADD_FAILURE() << threads << " taken";
    } catch (const OptionError& e) {
      EXPECT_EQ(std::string(e.what()), words + "'" + std::to_string(threads) + "'");
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ / "t.isotope"));
}

// The mesh's arrays reach code that takes a std::span (the views), or a std::vector of its own (a
// copy), whatever allocator the mesh keeps them in.
TEST_F(PublicApi, AMeshIsTakenAsViewsOrCopiedIntoPlainVectors) {
  const Mesh mesh = extract(sphere(), {});
  ASSERT_GT(mesh.triangles.size(), 500u);
  const std::span<const std::array<float, 3>> vertices = mesh.vertices();
  const std::span<const std::array<uint32_t, 3>> faces = mesh.faces();
  EXPECT_EQ(vertices.data(), mesh.positions.data());
  EXPECT_EQ(vertices.size(), mesh.positions.size());
  EXPECT_EQ(faces.data(), mesh.triangles.data());
  EXPECT_EQ(faces.size(), mesh.triangles.size());
  const std::vector<std::array<uint32_t, 3>> own(faces.begin(), faces.end());
  ASSERT_EQ(own.size(), mesh.triangles.size());
  EXPECT_TRUE(std::equal(own.begin(), own.end(), mesh.triangles.begin()));
}

// The context's threads bound the call while it runs (seen from its progress, which runs inside
// it), and its progress hears the hierarchy that the extraction builds; the mesh is the same bytes
// under any context.
TEST_F(PublicApi, ARunContextChangesHowACallRunsNotWhatItGives) {
  const Volume v = sphere();
  ExtractOptions o;
  o.eps = 0.25;
  const Mesh reference = extract(v, o);
  ASSERT_GT(reference.triangles.size(), 500u);
  for (const int threads : {1, 2, 0}) {
    const Source source = open_volume(v);
    std::vector<size_t> seen;
    RunContext run;
    run.threads = threads;
    run.progress = [&](double) {
      seen.push_back(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
    };
    const Mesh mesh = source.extract(o, run);
    EXPECT_TRUE(mesh.positions == reference.positions && mesh.triangles == reference.triangles) << threads;
    ASSERT_FALSE(seen.empty()) << "the build's progress is heard; " << threads << " threads";
    if (threads > 0) {
      for (const size_t limit : seen) EXPECT_EQ(limit, static_cast<size_t>(threads));
    }
    seen.clear();
    source.extract(o, run);
    EXPECT_TRUE(seen.empty()) << "the hierarchy is built once";
  }
}

// A cancel flag set while a Source builds its hierarchy (a first coarse extraction) stops the build
// as it stops an extraction, with ExtractionCancelled, and leaves no half-made hierarchy: the next
// extraction builds it whole and gives the mesh a fresh Source gives.
TEST_F(PublicApi, ACancelStopsTheHierarchyASourceBuildsAndLeavesItToBeBuiltAgain) {
  const Volume v = sphere();
  ExtractOptions o;
  o.eps = 0.25;
  const Mesh reference = open_volume(v).extract(o);
  for (const bool file : {false, true}) {  // the array's hierarchy, and a raw file's
    SCOPED_TRACE(file ? "a raw file" : "an array");
    const std::string raw = path("sphere_33x33x33_float32.raw");
    if (file)
      std::ofstream(raw, std::ios::binary)
          .write(reinterpret_cast<const char*>(v.values.data()), static_cast<std::streamsize>(v.values.size() * 4));
    const Source source = file ? open_volume({raw, std::nullopt, std::nullopt}) : open_volume(v);
    std::atomic<bool> stop{false};
    RunContext run;
    run.cancel = &stop;
    run.progress = [&](double) { stop = true; };  // set at the build's first report
    expect_error<ExtractionCancelled>([&] { source.extract(o, run); }, "cancelled");
    EXPECT_TRUE(stop);
    EXPECT_FALSE(source.info().hierarchy_built);
    const Mesh mesh = source.extract(o);
    EXPECT_TRUE(mesh.positions == reference.positions && mesh.triangles == reference.triangles);
  }
}

}  // namespace
}  // namespace isotope

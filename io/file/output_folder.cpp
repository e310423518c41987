#include "io/file/output_folder.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <optional>
#include <set>
#include <system_error>
#include <utility>

#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

constexpr const char* kManifestHeader = "isotope output folder 1";

// The folder writing PATH replaces: PATH with every symbolic link followed, made absolute.
// Throws IoError when it exists and is not a folder, or the links loop.
fs::path folder_target(const NamedPath& output) {
  const std::string& path = output.path;
  if (path.empty()) throw IoError(output.what + ": the path is empty");
  // "DIR/" is DIR: lstat of "link/" would follow the link and lose it.
  std::string named = path;
  while (named.size() > 1 && named.back() == '/') named.pop_back();
  fs::path target = named;
  for (int links = 0;; ++links) {
    struct stat st {};
    if (::lstat(target.c_str(), &st) != 0 || S_ISDIR(st.st_mode)) break;
    if (!S_ISLNK(st.st_mode))
      throw IoError(output.what + " " + path + ": " +
                    (target.string() == named ? "is" : "names '" + target.string() + "',") +
                    " not a folder; isotope writes a new folder there and never replaces a file with it");
    if (links == 40) throw IoError(output.what + " " + path + ": too many levels of symbolic links");
    std::error_code ec;
    const fs::path next = fs::read_symlink(target, ec);
    if (ec) throw IoError(output.what + " " + path + ": cannot read the symbolic link '" + target.string() + "'");
    target = next.is_absolute() ? next : target.parent_path() / next;
  }
  fs::path normal = fs::absolute(target).lexically_normal();
  return normal.has_filename() ? normal : normal.parent_path();  // "DIR/" is DIR
}

// The names an earlier folder's manifest lists, or nullopt when it has none that isotope wrote.
std::optional<std::set<std::string>> manifest_names(const fs::path& folder) {
  struct stat st {};
  const fs::path manifest = folder / OutputFolder::kManifestName;
  if (::lstat(manifest.c_str(), &st) != 0 || !S_ISREG(st.st_mode) || st.st_size > (1 << 24)) return std::nullopt;
  std::ifstream in(manifest);
  std::string line;
  if (!std::getline(in, line) || line != kManifestHeader) return std::nullopt;
  std::set<std::string> names;
  while (std::getline(in, line)) {
    // A plain name within the folder, never a path that leads out of it.
    if (line.empty() || line == "." || line == ".." || line.find('/') != std::string::npos ||
        line == OutputFolder::kManifestName)
      return std::nullopt;
    names.insert(line);
  }
  return names;
}

// What TARGET holds now: nothing (missing or empty, nullopt) or an earlier output's listed names.
// Throws IoError naming the first entry isotope did not write.
std::optional<std::set<std::string>> replaceable(const NamedPath& output, const fs::path& target) {
  std::error_code ec;
  if (!fs::exists(target, ec)) {
    const fs::path parent = target.parent_path();
    if (!fs::is_directory(parent, ec))
      throw IoError("cannot write '" + output.path + "': directory '" + parent.string() + "' does not exist");
    return std::nullopt;
  }
  std::vector<std::string> entries;
  for (fs::directory_iterator it(target, ec), end; !ec && it != end; it.increment(ec))
    entries.push_back(it->path().filename().string());
  if (ec) throw IoError(output.what + " " + output.path + ": cannot list the folder: " + ec.message());
  if (entries.empty()) return std::nullopt;
  std::sort(entries.begin(), entries.end());
  const auto names = manifest_names(target);
  const std::string refusal = output.what + " " + output.path + ": ";
  const std::string advice =
      "; isotope replaces only a new or empty folder or one it wrote before, and never deletes a "
      "file it did not write";
  if (!names) {
    // Parts an isotope before the manifest wrote: the same names, and nothing else.
    const bool old_parts = std::all_of(entries.begin(), entries.end(), [](const std::string& e) {
      return e == "mesh.pvtp" || (e.size() == 14 && e.rfind("part-", 0) == 0 && e.ends_with(".vtp"));
    });
    if (old_parts)
      throw IoError(refusal + "holds the parts of an earlier isotope, which wrote no " + OutputFolder::kManifestName +
                    "; remove them or give a new folder" + advice);
    throw IoError(refusal + "is a folder that isotope did not write (it holds '" + entries.front() + "' and no " +
                  OutputFolder::kManifestName + ")" + advice);
  }
  for (const std::string& e : entries) {
    if (e == OutputFolder::kManifestName) continue;
    struct stat st {};
    const bool regular = ::lstat((target / e).c_str(), &st) == 0 && S_ISREG(st.st_mode);
    if (!names->count(e) || !regular)
      throw IoError(refusal + "holds '" + e + "', which isotope did not write" + advice);
  }
  return names;
}

void sync_directory(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  (void)::close(fd);
}

}  // namespace

void OutputFolder::check(const NamedPath& output, const std::vector<NamedPath>& inputs) {
  const fs::path target = folder_target(output);
  std::error_code canonical_error;
  fs::path folder = fs::weakly_canonical(target, canonical_error);
  if (canonical_error || folder.empty()) folder = target;
  for (const NamedPath& input : inputs) {
    if (input.path.empty()) continue;
    std::error_code ec;
    fs::path file = input.path;
    // FILE.h5:/dataset names a file before its last ":/" (as read_volume splits it).
    const size_t split = input.path.rfind(":/");
    if (!fs::exists(file, ec) && split != std::string::npos) file = input.path.substr(0, split);
    if (!fs::exists(file, ec)) continue;  // its reader says so
    const fs::path canonical = fs::weakly_canonical(file, ec);
    if (ec) continue;
    const auto [end, rest] = std::mismatch(folder.begin(), folder.end(), canonical.begin(), canonical.end());
    if (end == folder.end())  // the input is the target or lies within it
      throw IoError(output.what + " " + output.path + ": holds " + input.what + " " + input.path +
                    "; isotope never replaces a folder that holds its input");
  }
  replaceable(output, target);
}

OutputFolder::OutputFolder(NamedPath output) : output_(std::move(output)), target_(folder_target(output_)) {
  const std::string base = "." + target_.filename().string() + ".tmp." + std::to_string(::getpid()) + ".";
  for (int n = 0; path_.empty(); ++n) {
    const fs::path p = target_.parent_path() / (base + std::to_string(n));
    std::error_code ec;
    if (fs::create_directory(p, ec)) path_ = p;
    if (ec || n > 100)
      throw IoError(output_.what + " " + output_.path + ": cannot make a new folder beside it" +
                    (ec ? ": " + ec.message() : std::string()));
  }
}

OutputFolder::~OutputFolder() {
  std::error_code ignored;
  if (!committed_ && !path_.empty()) fs::remove_all(path_, ignored);
}

void OutputFolder::commit(const std::vector<std::string>& files) {
  {
    std::string text = std::string(kManifestHeader) + "\n";
    for (const std::string& f : files) text += f + "\n";
    AtomicFile manifest((path_ / kManifestName).string());
    manifest.write(text.data(), text.size());
    manifest.commit();
  }
  const std::optional<std::set<std::string>> earlier = replaceable(output_, target_);
  const fs::path parent = target_.parent_path();
  std::error_code ec;
  if (!earlier) {  // missing or empty: rename(2) replaces an empty folder in one step
    fs::rename(path_, target_, ec);
    if (ec)
      throw IoError(output_.what + " " + output_.path + ": cannot put the new folder in its place: " + ec.message() +
                    " (was something written into it meanwhile?)");
    committed_ = true;
    sync_directory(parent);
    return;
  }
  // An earlier output: moved aside, the new one put in its place, then the files its manifest lists
  // removed. A file that appeared in it in the moment between the check and the move stays there.
  const fs::path aside = parent / ("." + target_.filename().string() + ".old." + std::to_string(::getpid()));
  fs::rename(target_, aside, ec);
  if (ec) throw IoError(output_.what + " " + output_.path + ": cannot move the earlier folder aside: " + ec.message());
  fs::rename(path_, target_, ec);
  if (ec) {
    std::error_code ignored;
    fs::rename(aside, target_, ignored);  // the earlier output back in place
    throw IoError(output_.what + " " + output_.path + ": cannot put the new folder in its place: " + ec.message());
  }
  committed_ = true;
  sync_directory(parent);
  for (const std::string& name : *earlier) {
    struct stat st {};
    const fs::path p = aside / name;
    if (::lstat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode)) ::unlink(p.c_str());
  }
  ::unlink((aside / kManifestName).c_str());
  ::rmdir(aside.c_str());
}

}  // namespace isotope

#pragma once
// A folder of files written as one output (isotope extract --parts: one mesh per rank and the
// index naming them), under the output policy of AtomicFile carried to folders:
// - the files are written into a new folder beside the target, which takes the target's place
//   only when complete (commit); destroyed before that, it is removed with what it holds;
// - the target may be missing, an empty folder, or a folder this class wrote before, recognised by
//   its manifest (kManifestName: the files written, one name a line) and holding nothing else;
//   anything else is refused with an IoError naming what is in the way, before any work (check)
//   and again when the folder is swapped in;
// - a folder that holds an input (or is one) is refused, by name;
// - of an earlier folder, only the files its manifest lists are removed, never another;
// - a symbolic link to a folder is followed: the folder it names is replaced, the link stays.
#include <filesystem>
#include <string>
#include <vector>

#include "io/file/atomic_file.h"  // NamedPath

namespace isotope {

class OutputFolder {
 public:
  static constexpr const char* kManifestName = "isotope-manifest.txt";

  // Throws IoError unless TARGET (named by OUTPUT.what, e.g. "--parts") may be replaced as above,
  // and names none of INPUTS. Creates nothing.
  static void check(const NamedPath& output, const std::vector<NamedPath>& inputs);

  // Makes the new, empty folder beside OUTPUT's target (check first). Throws IoError.
  explicit OutputFolder(NamedPath output);
  ~OutputFolder();  // removes the new folder and its files unless committed
  OutputFolder(const OutputFolder&) = delete;
  OutputFolder& operator=(const OutputFolder&) = delete;

  // Where the files go until commit.
  const std::filesystem::path& path() const { return path_; }
  // Writes the manifest of FILES (names within path()), checks the target again, and puts the new
  // folder in its place; an earlier folder's listed files are removed afterwards. Throws IoError.
  void commit(const std::vector<std::string>& files);

 private:
  NamedPath output_;
  std::filesystem::path target_, path_;
  bool committed_ = false;
};

}  // namespace isotope

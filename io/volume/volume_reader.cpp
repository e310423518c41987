#include "io/volume/volume_reader.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <system_error>

#include "io/file/extension.h"
#include "io/file/input_file.h"
#include "io/volume/hdf5_reader.h"
#include "io/volume/nrrd_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/tiff_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

struct Hdf5Spec {
  std::string file, dataset;
};

// "FILE:/dataset", split at the last ':' followed by '/', so ':' may appear earlier in FILE.
// A spec that names an existing file as a whole is never split.
std::optional<Hdf5Spec> split_hdf5_spec(const std::string& spec) {
  std::error_code ec;
  if (fs::exists(spec, ec)) return std::nullopt;
  const size_t colon = spec.rfind(":/");
  if (colon == std::string::npos || colon == 0) return std::nullopt;
  return Hdf5Spec{spec.substr(0, colon), spec.substr(colon + 1)};
}

bool has_hdf5_extension(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  return ext == ".h5" || ext == ".hdf5";
}

bool has_nrrd_extension(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  return ext == ".nrrd" || ext == ".nhdr";
}

std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& s : items) out += (out.empty() ? "" : ", ") + s;
  return out;
}

std::string only_3d_dataset(const std::string& file) {
  const auto names = list_3d_datasets(file);
  if (names.size() == 1) return names.front();
  if (names.empty()) throw IoError(file + ": contains no 3-D numeric dataset");
  throw IoError(file + ": contains several 3-D datasets (" + join(names) + "); name one as " + file + ":/DATASET");
}

RawLayout raw_layout(const VolumeSpec& source) {
  // Command-line values win over the name, field by field.
  const auto from_name = parse_raw_name(source.path);
  auto dims = source.dims;
  auto type = source.type;
  if (!dims && from_name) dims = from_name->dims;
  if (!type && from_name) type = from_name->type;
  if (dims && type) return RawLayout{*dims, *type};
  const char* missing = !dims && !type ? "dimensions and type" : !dims ? "dimensions" : "type";
  throw IoError(source.path + ": cannot tell the " + missing +
                " from the file name (expected NAME_XxYxZ_TYPE.raw); pass --dims and --type");
}

}  // namespace

VolumeLocation locate_volume(const VolumeSpec& source) {
  using Format = VolumeLocation::Format;
  if (source.path.empty()) throw IoError("no volume file given");
  if (const auto h5 = split_hdf5_spec(source.path)) return {Format::hdf5, h5->file, h5->dataset, {}};
  if (has_hdf5_extension(source.path)) return {Format::hdf5, source.path, only_3d_dataset(source.path), {}};
  if (has_nrrd_extension(source.path)) return {Format::nrrd, source.path, "", {}};  // the header says dims and type
  if (is_tiff_stack(source.path)) return {Format::tiff, source.path, "", {}};       // so do the pages
  require_regular_file(source.path, source.path, "a volume file");  // a mistyped path says so, not "pass --dims"
  return {Format::raw, source.path, "", raw_layout(source)};
}

Volume read_volume(const VolumeSpec& source) {
  const VolumeLocation at = locate_volume(source);
  Volume v;
  switch (at.format) {
    case VolumeLocation::Format::hdf5: v = read_hdf5(at.file, at.dataset); break;
    case VolumeLocation::Format::nrrd: v = read_nrrd(at.file); break;
    case VolumeLocation::Format::tiff: v = read_tiff_stack(at.file); break;
    case VolumeLocation::Format::raw: v = read_raw(at.file, at.layout); break;
  }
  check_volume_layout(v.dims, v.spacing, v.origin, at.file);
  return v;
}

}  // namespace isotope

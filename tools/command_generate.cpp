// isotope generate: synthetic volumes with known isosurfaces (the engine's synthetic fields), written as
// .raw (x fastest; float32, or uint8/uint16 stretched over the field's range) or as float32
// HDF5 dataset /volume, chosen by the output's extension.
#include <CLI/CLI.hpp>
#include <array>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/synthetic/fields.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_writer.h"
#include "tools/commands.h"

namespace isotope::tools {
namespace {

struct GenerateArgs {
  std::string shape;
  int64_t size = 65;
  std::string shift;
  uint64_t seed = 1;
  int bumps = 24;
  std::string output;
  std::string type = "float32";
  bool quiet = false;
};

const std::vector<std::string> kShapes = {"algebraic", "sphere", "torus", "linked-tori", "nested-spheres", "noise"};

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// {9,9,9}, uint16 -> "9x9x9 uint16".
std::string layout_text(const std::array<int64_t, 3>& dims, ScalarType type) {
  return std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " " +
         scalar_type_name(type);
}

// "5/32,3/32,0" -> {0.15625, 0.09375, 0}.
std::optional<std::array<double, 3>> parse_shift(const std::string& text) {
  std::array<double, 3> v{};
  size_t pos = 0;
  for (size_t axis = 0; axis < 3; ++axis) {
    const size_t comma = axis < 2 ? text.find(',', pos) : text.size();  // the last takes the rest
    if (comma == std::string::npos) return std::nullopt;
    const auto x = parse_real(text.substr(pos, comma - pos));
    if (!x || !std::isfinite(*x)) return std::nullopt;
    v[axis] = *x;
    pos = comma + 1;
  }
  return v;
}

// A raw name that states a layout must state the one written, or reading it back would fail
// on the size or, worse, decode the bytes as another type of the same width.
void check_name_matches(const GenerateArgs& a, ScalarType type) {
  const auto named = parse_raw_name(a.output);
  if (!named) return;
  if (named->dims != std::array<int64_t, 3>{a.size, a.size, a.size} || named->type != type) {
    throw CLI::ValidationError("-o", "the name says " + layout_text(named->dims, named->type) + " but the volume is " +
                                         layout_text({a.size, a.size, a.size}, type) + ": " + a.output);
  }
}

// The stretch of an integer encoding, so that isovalues can be chosen in the stored codes.
void print_encoding(const RawEncoding& e) {
  if (!e.is_mapped()) return;
  const std::string first = e.first != 0 ? std::to_string(static_cast<long long>(e.first)) + " + " : "";
  std::printf("%s codes: code(v) = %s(v - (%.9g)) * %.9g, stored rounded; min %.9g -> %g, max %.9g -> %g",
              scalar_type_name(e.type), first.c_str(), e.min, e.scale, e.min, e.code(e.min), e.max,
              std::round(e.code(e.max)));
  if (e.min <= 0 && 0 <= e.max) std::printf("; iso 0 -> %.9g", e.code(0));
  std::printf("\n");
}

int run_generate(const GenerateArgs& a, CLI::App* cmd) {
  const bool raw = ends_with(a.output, ".raw");
  const bool h5 = ends_with(a.output, ".h5") || ends_with(a.output, ".hdf5");
  if (!raw && !h5) throw CLI::ValidationError("-o", "the output must end in .raw or .h5/.hdf5: " + a.output);
  const ScalarType type = *parse_scalar_type(a.type);
  if (h5 && type != ScalarType::float32)
    throw CLI::ValidationError("--type", "HDF5 output is float32; --type applies to .raw");
  check_name_matches(a, type);
  if (cmd->count("--shift") > 0 && a.shape != "algebraic") {
    throw CLI::ValidationError("--shift", "only the algebraic field takes --shift");
  }
  if ((cmd->count("--seed") > 0 || cmd->count("--bumps") > 0) && a.shape != "noise") {
    throw CLI::ValidationError("--seed/--bumps", "only the noise field takes --seed and --bumps");
  }

  Volume v;
  if (a.shape == "algebraic") {
    v = generate_algebraic(a.size, a.shift.empty() ? std::array<double, 3>{0, 0, 0} : *parse_shift(a.shift));
  } else if (a.shape == "sphere") {
    v = generate_sphere(a.size);
  } else if (a.shape == "torus") {
    v = generate_torus(a.size);
  } else if (a.shape == "linked-tori") {
    v = generate_linked_tori(a.size);
  } else if (a.shape == "nested-spheres") {
    v = generate_nested_spheres(a.size);
  } else {
    v = generate_noise(a.size, a.seed, a.bumps);
  }

  RawEncoding encoding;
  if (raw) {
    encoding = write_raw(v, a.output, type);
  } else {
    write_hdf5(v, a.output);
  }
  if (!a.quiet) {
    const std::string layout = layout_text(v.dims, type);
    std::printf("%s: %s field, %s%s\n", a.output.c_str(), a.shape.c_str(), layout.c_str(),
                h5 ? ", dataset /volume" : "");
    print_encoding(encoding);
    if (raw && !parse_raw_name(a.output)) {
      std::printf("note: the name does not carry the layout; extract it with --dims %s --type %s\n",
                  layout.substr(0, layout.find(' ')).c_str(), scalar_type_name(type));
    }
  }
  return 0;
}

}  // namespace

Command add_generate_command(CLI::App& app) {
  auto a = std::make_shared<GenerateArgs>();
  CLI::App* cmd = app.add_subcommand(
      "generate",
      "Write a synthetic volume on [-1,1]^3: the paper's algebraic function (Table 1), closed test shapes\n"
      "(positive inside, surface at 0) or a smooth random field");
  cmd->add_option("SHAPE", a->shape,
                  "algebraic | sphere (1 component, chi 2) | torus (1, chi 0) | linked-tori (2, chi 0) |\n"
                  "nested-spheres (3, chi 6) | noise (sum of random Gaussians, in [-1,1])")
      ->required()
      ->check(CLI::IsMember(kShapes));
  cmd->add_option("--size", a->size, "Nodes per axis")
      ->check(CLI::Range(int64_t{2}, int64_t{4097}))
      ->capture_default_str();
  cmd->add_option("--shift", a->shift,
                  "algebraic: move the singularity to (X,Y,Z); fractions allowed, e.g. 5/32,3/32,0")
      ->type_name("X,Y,Z")
      ->check(CLI::Validator(
          [](std::string& s) -> std::string {
            return parse_shift(s) ? std::string() : "must be three numbers X,Y,Z, got '" + s + "'";
          },
          ""));
  cmd->add_option("--seed", a->seed, "noise: random seed")->capture_default_str();
  cmd->add_option("--bumps", a->bumps, "noise: number of Gaussians")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("-o,--output", a->output, "Output: FILE.raw (--type, x fastest) or FILE.h5 (float32 dataset /volume)")
      ->required()
      ->type_name("FILE");
  cmd->add_option("--type", a->type,
                  ".raw value type; uint8/uint16 map the field's [min, max] onto [0, 255] / [0, 65535],\n"
                  "rounded, and print the mapping (HDF5 output is always float32)")
      ->check(CLI::IsMember({"uint8", "uint16", "float32"}))
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", a->quiet, "Print nothing on success");
  return [a, cmd] { return run_generate(*a, cmd); };
}

}  // namespace isotope::tools

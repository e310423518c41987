// isotope extract: volume -> adaptive isosurface (PLY, OBJ, STL, glTF or VTK, by -o's extension) +
// optional JSON report.
// Steps: open the input as an isotope::Source, extract (a raw volume at eps > 0 is read and its
// hierarchy built in memory first; eps 0 streams the file through the march), measure topology,
// write.
// Nothing is written before the mesh exists, and the writers are atomic, so a failure
// leaves no output file behind.

#include <oneapi/tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "engine/core/byte_codec.h"
#include "engine/diagnostics/component_report.h"
#include "engine/extract/extract_drivers.h"
#include "io/file/atomic_file.h"
#include "io/file/output_folder.h"
#include "io/mesh/mesh_writer.h"
#include "io/volume/volume_reader.h"
#include "isotope/error.h"
#include "isotope/mesh.h"
#include "isotope/source.h"
#include "tools/commands.h"
#include "tools/support/peak_memory.h"
#include "tools/support/report.h"

namespace isotope::tools {
namespace {

struct ExtractArgs {
  std::string input;
  std::string iso;
  std::string eps = "0";
  std::string error = "bound";
  std::string topology = "preserve";
  std::string weight;
  std::string delta;
  bool compare_full = false;
  // --compare-full relates components whose surfaces lie within this many voxel spacings: a
  // coarse mesh moves the surface by up to a few voxels (compare_components).
  double compare_voxels = 3;
  std::string dims;
  std::string type;
  std::string output;
  std::string parts;  // --parts DIR: one .vtp per rank and DIR/mesh.pvtp
  std::string report;
  int threads = 0;
  int64_t cache_mb = OpenOptions{}.cache_mb;
  std::string focus;
  std::string radius;
  std::string max_triangles;
  std::string eps_ties;
  bool quiet = false;
};

// --compare-full: the same isovalue at full resolution (eps = 0 equals marching tetrahedra on
// every cell), from the same source, so a store is read out of core again.
ExtractOptions full_resolution(const ExtractOptions& o) {
  ExtractOptions full;
  full.iso = o.iso;
  full.eps = 0;
  full.topology = TopologyMode::none;
  return full;
}

int write_outputs(const ExtractArgs& a, ExtractionRun& run, Mesh& mesh, const Mesh& full);

// --parts DIR: every rank writes its share's mesh as part-RRRRR.vtp into a new folder beside DIR,
// rank 0 adds mesh.pvtp naming them all (ParaView opens it as one dataset), and only then does the
// folder take DIR's place: a failure on any rank leaves DIR as it was (docs/DISTRIBUTED.md). DIR
// must be new, empty or an earlier --parts output holding nothing else (OutputFolder).
int write_parts(const ExtractArgs& a, const ExtractionRun& run, const Mesh& mesh) {
  const Distribution* group = process_group();
  const int rank = group ? group->rank() : 0, ranks = group ? group->ranks() : 1;
  auto part_name = [](int r) {
    char name[32];
    std::snprintf(name, sizeof name, "part-%05d.vtp", r);
    return std::string(name);
  };
  std::optional<OutputFolder> folder;  // rank 0's
  on_every_rank([&] {
    if (speaking_rank()) folder.emplace(NamedPath{"--parts", a.parts});
  });
  std::filesystem::path temp = folder ? folder->path() : std::filesystem::path();
  if (group) {  // rank 0's folder, to every rank
    ByteWriter w;
    w.put_array(temp.string());
    const std::vector<std::vector<uint8_t>> all = group->all_gather(w.bytes());
    ByteReader r(all[0]);
    std::string path;
    r.get_array(path);
    temp = path;
  }
  on_every_rank([&] {
    AtomicFile part((temp / part_name(rank)).string());
    write_mesh(mesh, part, MeshFormat::vtp);
    part.commit();
  });
  int64_t vertices = static_cast<int64_t>(mesh.positions.size()),
          triangles = static_cast<int64_t>(mesh.triangles.size());
  if (group) {  // the totals, for the summary
    ByteWriter w;
    w.put(vertices);
    w.put(triangles);
    vertices = triangles = 0;
    for (const std::vector<uint8_t>& bytes : group->all_gather(w.bytes())) {
      ByteReader r(bytes);
      vertices += r.get<int64_t>();
      triangles += r.get<int64_t>();
    }
  }
  on_every_rank([&] {
    if (!speaking_rank()) return;
    std::vector<std::string> pieces;
    for (int r = 0; r < ranks; ++r) pieces.push_back(part_name(r));
    write_pvtp(pieces, (folder->path() / "mesh.pvtp").string());
    pieces.push_back("mesh.pvtp");
    folder->commit(pieces);
  });
  if (!a.quiet && speaking_rank())
    std::printf(
        "%s: %d part%s, %lld triangles, %lld vertices (those on a boundary between parts in both); extract "
        "%.3f s%s\n",
        (std::filesystem::path(a.parts) / "mesh.pvtp").c_str(), ranks, ranks == 1 ? "" : "s",
        static_cast<long long>(triangles), static_cast<long long>(vertices), run.extract_seconds,
        balance_text(run.extract.ranks).c_str());
  return 0;
}

int run_extract(const ExtractArgs& a) {
  const bool progress = progress_enabled(a.quiet);
  ExtractionRun run;
  run.input = a.input;
  run.output = a.output;
  // The extraction's options through the parser every face shares (isotope/extract.h): the
  // same words, ranges and relations as `isotope serve` and `isotope sweep`.
  std::vector<std::pair<std::string, std::string>> given = {
      {"iso", a.iso}, {"eps", a.eps}, {"error", a.error}, {"topology", a.topology}};
  for (const auto& [name, text] : {std::pair<const char*, const std::string&>{"weight", a.weight},
                                   {"delta", a.delta},
                                   {"focus", a.focus},
                                   {"radius", a.radius},
                                   {"max-triangles", a.max_triangles},
                                   {"eps-ties", a.eps_ties}})
    if (!text.empty()) given.emplace_back(name, text);
  // A budget in simplify mode without a delta chooses delta too (the parser sets auto_delta).
  run.options = parse_command_line_options(given);
  if (a.compare_full && a.report.empty()) throw CLI::ValidationError("--compare-full", "needs --report");
  if (a.output.empty() == a.parts.empty()) throw CLI::ValidationError("-o", "give either -o MESH or --parts DIR");
  if (!a.parts.empty() && !a.report.empty())
    throw CLI::ValidationError("--report", "needs one mesh (-o); --parts leaves it in pieces");
  // Below 2^-11 (about 0.00049) voxel spacings the comparison's sampling grid of a 2^19-node axis would overflow
  // (compare_components): refused here, before the work, not after it.
  if (!(a.compare_voxels >= 5e-4) || !std::isfinite(a.compare_voxels) || a.compare_voxels > 1e6) {
    char shown[32];
    std::snprintf(shown, sizeof shown, "%g", a.compare_voxels);  // 1e-300, not 0.000000
    throw CLI::ValidationError("--compare-voxels",
                               std::string("must be a number of voxel spacings in [0.0005, 1e6], got ") + shown);
  }

  // Fail before the (possibly long) extraction when the outputs cannot be written; creates nothing.
  // Under mpirun rank 0 writes them (--parts: every rank, into a folder rank 0 makes), and checks
  // them for all.
  on_every_rank([&] {
    if (!speaking_rank()) return;
    for (const std::string* path : {&a.output, &a.report, &a.parts}) {
      if (path->empty()) continue;
      const std::filesystem::path dir = std::filesystem::path(*path).parent_path();
      if (!dir.empty() && !std::filesystem::is_directory(dir)) {
        throw IoError("cannot write '" + *path + "': directory '" + dir.string() + "' does not exist");
      }
    }
    if (a.parts.empty())
      check_outputs({{"INPUT", a.input}}, {{"-o", a.output}, {"--report", a.report}});
    else
      OutputFolder::check({"--parts", a.parts}, {{"INPUT", a.input}});
  });

  std::optional<tbb::global_control> threads;
  if (a.threads > 0) {
    threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(a.threads));
  }
  run.threads = static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));

  // Under mpirun every rank opens the input and extracts its share; rank 0 gets the mesh and does
  // the rest (docs/DISTRIBUTED.md). Each step that one rank may fail alone is settled among all.
  RunContext context = preprocessing_context(progress);
  context.distribution = process_group();
  context.keep_shares = !a.parts.empty();
  Mesh mesh, full;
  {  // scoped: the input's memory (volume or brick cache) is given back before measuring and writing
    std::optional<Source> opened;
    on_every_rank([&] {
      opened.emplace(open_input(a.input, a.dims, a.type, a.cache_mb, progress));
      // A volume's hierarchy, if the extraction needs one, built here, where a rank that runs out
      // of memory stops them all (a store needs nothing).
      if (process_group()) opened->prepare({run.options}, context);
    });
    const Source& input = *opened;
    const double read_before = input.info().read_seconds;
    const auto start = std::chrono::steady_clock::now();
    mesh = input.extract(run.options, context, &run.extract);
    const double elapsed = seconds_since(start);
    describe(input.info(), run);  // before --compare-full: the cache's reads are the extraction's own
    // A volume file is read whole, and its hierarchy built, on demand inside the extraction: that
    // part is reading and preprocessing (under mpirun both were done before, above). A file
    // streamed at eps 0 is read while it is marched, in one process or under mpirun: its reading
    // is part of the extraction's time.
    run.extract_seconds = elapsed - (run.read_seconds - read_before) - (process_group() ? 0.0 : run.preprocess_seconds);
    if (progress) std::fprintf(stderr, "isotope: extracted in %.3f s\n", run.extract_seconds);
    if (a.compare_full) {
      const auto compare_start = std::chrono::steady_clock::now();
      RunContext shared;  // among the same processes, one mesh on rank 0
      shared.distribution = context.distribution;
      full = input.extract(full_resolution(run.options), shared);
      run.compare_seconds = seconds_since(compare_start);
    }
  }
  if (!a.parts.empty()) return write_parts(a, run, mesh);
  int code = 0;
  on_every_rank([&] {
    if (speaking_rank()) code = write_outputs(a, run, mesh, full);
  });
  return code;
}

// Rank 0's (or the one process's) part: measure the mesh, write it and the report.
int write_outputs(const ExtractArgs& a, ExtractionRun& run, Mesh& mesh, const Mesh& full) {
  // Both outputs are written to temporary files and finished (flushed to disk) before either is
  // renamed into place (AtomicFile): a failure on the way, a full disk included, leaves the
  // files named by -o and --report as they were. On more than one thread the mesh is written while
  // its topology is measured: the write ends waiting for the disk (fsync), which the measuring
  // overlaps.
  const MeshFormat format = *mesh_format_of(a.output);  // checked when parsed
  AtomicFile mesh_file(a.output);
  std::optional<AtomicFile> report_file;
  if (!a.report.empty()) report_file.emplace(a.report);
  std::exception_ptr write_error;
  std::thread writer;
  if (run.threads > 1)
    writer = std::thread([&] {
      try {
        write_mesh(mesh, mesh_file, format);
      } catch (...) {
        write_error = std::current_exception();
      }
    });
  try {
    const auto start = std::chrono::steady_clock::now();
    // The topology is measured for the summary line and the report only: with --quiet and no
    // report nobody reads it (embryo eps 0, 2 threads: 249 -> 183 ms for the whole process).
    // With a report, the totals of its components: the mesh's edges found once.
    const MeshComponents components = a.report.empty() ? MeshComponents{} : label_components(mesh);
    if (!a.report.empty())
      run.topology = total_topology(components.components);
    else if (!a.quiet)
      run.topology = measure_topology(mesh);
    run.components = components.components;
    run.measure_seconds = seconds_since(start);
    if (a.compare_full) {
      const auto compare_start = std::chrono::steady_clock::now();
      run.compare_tolerance = a.compare_voxels * std::max({run.spacing[0], run.spacing[1], run.spacing[2]});
      run.comparison = compare_components(full, label_components(full), mesh, components, run.compare_tolerance);
      run.compare_seconds += seconds_since(compare_start);
    }
  } catch (...) {
    if (writer.joinable()) writer.join();
    throw;
  }
  if (writer.joinable()) writer.join();
  if (write_error) std::rethrow_exception(write_error);
  run.peak_rss_mb = static_cast<double>(peak_rss_bytes()) / (1 << 20);  // this process so far
  if (run.threads <= 1) write_mesh(mesh, mesh_file, format);
  if (report_file) {
    const std::string text = report_json(run).dump(2) + "\n";
    report_file->write(text.data(), text.size());
    report_file->finish();
  }
  mesh_file.commit();
  if (report_file) report_file->commit();
  if (!a.quiet) std::cout << summary_line(run) << std::endl;
  if (!a.quiet && run.comparison) std::cout << comparison_line(*run.comparison) << std::endl;
  return 0;
}

}  // namespace

Command add_extract_command(CLI::App& app) {
  auto a = std::make_shared<ExtractArgs>();
  CLI::App* cmd = app.add_subcommand(
      "extract", "Extract an adaptive isosurface from a volume into a mesh (PLY, OBJ, STL, glTF, VTK)");
  cmd->add_option("INPUT", a->input,
                  "Store made by 'isotope convert', or a volume: NAME_XxYxZ_TYPE.raw, any .raw with --dims/--type, "
                  "FILE.h5:/path/to/dataset, .nrrd/.nhdr")
      ->required();
  cmd->add_option("--iso", a->iso, "Isovalue (inside means value > iso)")
      ->required()
      ->check(extract_option_check("iso"))
      ->type_name("V");
  cmd->add_option("--eps", a->eps, "Error threshold: refine while the error indicator is >= eps; 0 = full resolution")
      ->check(extract_option_check("eps"))
      ->type_name("E")
      ->capture_default_str();
  cmd->add_option("--error", a->error,
                  "Error indicator: bound (guaranteed L-infinity bound of the coarse field) or surplus (the paper's)")
      ->check(extract_option_check("error"))
      ->capture_default_str();
  cmd->add_option("--topology", a->topology,
                  "Topology control: none, paper (the paper's critical intervals), preserve (exact local rule) or "
                  "simplify (preserve, but drop critical points whose --weight is below --delta)")
      ->check(extract_option_check("topology"))
      ->capture_default_str();
  cmd->add_option("--weight", a->weight,
                  "With --topology simplify: interval (|X|, value units, the default), gradient (|X| times the "
                  "steepest gradient around the critical point, value^2 per voxel) or size (full-resolution "
                  "tetrahedra the feature's isosurfaces cut)")
      ->check(extract_option_check("weight"))
      ->type_name("W");
  cmd->add_option("--delta", a->delta,
                  "With --topology simplify: keep critical points of weight >= D; 0 = preserve, larger = simpler "
                  "(isotope info STORE prints the largest weights)")
      ->check(extract_option_check("delta"))
      ->type_name("D");
  cmd->add_option("--dims", a->dims, "Raw input: nodes per axis, e.g. 301x324x56 (overrides the file name)")
      ->check(CLI::Validator(
          [](std::string& s) -> std::string {
            const auto d = parse_dims(s);
            if (!d) return "must look like 64x64x32, got '" + s + "'";
            return {};
          },
          ""))
      ->type_name("XxYxZ");
  cmd->add_option("--type", a->type, "Raw input: value type (overrides the file name)")
      ->check(CLI::IsMember({"uint8", "uint16", "int16", "float32", "float64"}));
  cmd->add_option("-o,--output", a->output,
                  "Output mesh, its format by extension: .ply (binary), .obj, .stl (binary), .glb (glTF), .vtp "
                  "(ParaView)")
      ->check(CLI::Validator(
          [](std::string& s) -> std::string { return mesh_format_of(s) ? "" : unknown_mesh_format_message(s); }, ""))
      ->type_name("MESH");
  cmd->add_option("--parts", a->parts,
                  "Instead of -o: the mesh in parts, one per rank under mpirun (DIR/part-00000.vtp, ...), and "
                  "DIR/mesh.pvtp naming them, which ParaView opens as one (docs/DISTRIBUTED.md)")
      ->type_name("DIR");
  cmd->add_option("--report", a->report,
                  "Write a JSON report: counts, timings, and per connected component its triangles, Euler "
                  "characteristic, genus, bounding box, area and volume")
      ->type_name("REPORT.json");
  cmd->add_flag("--compare-full", a->compare_full,
                "With --report: also extract the full-resolution surface (out of core for a store) and name what "
                "differs per component: lost, merged, split, handles closed");
  cmd->add_option("--compare-voxels", a->compare_voxels,
                  "With --compare-full: how far apart (in voxel spacings) surfaces of the same component may lie; "
                  "raise it for very coarse meshes (the report's samples_matched tells)")
      ->capture_default_str()
      ->type_name("V");
  cmd->add_option("--threads", a->threads, "Worker threads (0 = all cores)")
      ->check(thread_count_check())
      ->capture_default_str();
  cmd->add_option("--cache-mb", a->cache_mb,
                  "Memory for decoded bricks, in MB (at least 16 bricks, under 1 MB), of a store input or of a "
                  "volume's hierarchy (a store of its own); the store may be far larger")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_option("--focus", a->focus,
                  "Point of interest X,Y,Z (output coordinates): full resolution there, coarsening to eps at --radius")
      ->check(extract_option_check("focus"))
      ->type_name("X,Y,Z");
  cmd->add_option("--radius", a->radius, "With --focus: the distance at which the error threshold reaches eps")
      ->check(extract_option_check("radius"))
      ->type_name("R");
  cmd->add_option("--max-triangles", a->max_triangles,
                  "Instead of --eps (other than 0): the finest eps whose mesh has at most T triangles (T >= 1; on "
                  "volumes over 257 a side, one whose mesh has 90-100% of T, chosen from a sample, where one "
                  "does); with --topology simplify and no --delta, delta too: the features of smallest weight are "
                  "dropped until the "
                  "coarsest mesh takes half the budget")
      ->check(extract_option_check("max-triangles"))
      ->type_name("T");
  cmd->add_option("--eps-ties", a->eps_ties,
                  "With --eps: of the diamonds whose error equals eps exactly, refine only those of the N coarsest "
                  "tie classes (16 per level, coarse to fine; docs/METHOD.md): the finer steps --max-triangles "
                  "takes and reports, to reproduce its mesh")
      ->check(extract_option_check("eps-ties"))
      ->type_name("N");
  cmd->add_flag("-q,--quiet", a->quiet, "Print nothing on success");

  return [a] { return run_extract(*a); };
}

}  // namespace isotope::tools

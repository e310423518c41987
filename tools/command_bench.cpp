// isotope bench: the command's face over its benchmark suite (tools/bench).
#include <CLI/CLI.hpp>
#include <memory>

#include "tools/bench/bench_suite.h"
#include "tools/commands.h"

namespace isotope::tools {

Command add_bench_command(CLI::App& app) {
  auto a = std::make_shared<bench::SuiteOptions>();
  a->data = ISOTOPE_SHARED_DATA;
  CLI::App* cmd = app.add_subcommand(
      "bench",
      "Time extraction on a fixed suite against full-resolution marching tetrahedra, in the same run: from memory,\n"
      "from a warm and a cold store, one shot from the raw file; convert against its ceiling; scikit-image and\n"
      "VTK Flying Edges on the same array; the paper's Table 1; the targets met or missed");
  cmd->add_flag("--quick", a->quick, "The small suite (algebraic 65^3 and 257^3, the shared volumes): a few minutes");
  cmd->add_option("--json", a->json, "Also write every number as JSON")->type_name("F.json");
  cmd->add_option("--threads", a->threads, "Threads for the parallel rows (0 = all cores)")
      ->check(thread_count_check())
      ->capture_default_str();
  cmd->add_option("--dataset", a->datasets,
                  "Run only this dataset (repeatable): algebraic65, algebraic257, bolt,\n"
                  "hydrogen, ironProt, neghip, embryo, noise384, noise513, sphere512")
      ->type_name("NAME");
  cmd->add_option("--data", a->data, "Directory of the shared volumes (a volume missing there is an error)")
      ->type_name("DIR")
      ->capture_default_str();
  cmd->add_option("--work-dir", a->work_dir, "Where the temporary stores go (default: the system's temp directory)")
      ->type_name("DIR");
  cmd->add_option("--cache-mb", a->cache_mb, "Brick cache of the in-process store rows, in MB")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_flag("--scale", a->scale,
                "Instead of the suite: a generated N^3 uint8 volume (--scale-size, default 2048: 8.6 GB) written to\n"
                "--work-dir, converted with --memory-mb 1024 and extracted coarse with --cache-mb 256, beside eps 0\n"
                "from the raw file");
  cmd->add_option("--scale-size", a->scale_size, "With --scale: nodes per axis")
      ->check(CLI::Range(int64_t{65}, int64_t{8193}))
      ->capture_default_str();
  cmd->add_option(
         "--reference", a->reference,
         "Another isotope executable (another commit's: bench/build_reference.sh builds one): convert and the\n"
         "one-shot coarse surfaces of each dataset timed with it and with this one, whole processes in\n"
         "alternation, against the targets")
      ->type_name("FILE");
  cmd->add_flag("-q,--quiet", a->quiet, "No progress lines on stderr");
  return [a] { return bench::run_suite(*a); };  // an unknown --dataset: OptionError, a usage error
}

}  // namespace isotope::tools

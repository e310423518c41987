// isotope: multiresolution isosurfaces on a tetrahedral bisection hierarchy
// (Gerstner & Pajarola, IEEE Visualization 2000). Entry point and exit-code policy:
// 0 success (and --help, --version), 1 runtime failure, 2 usage error.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <exception>
#include <iostream>
#include <new>
#include <string>

#include "io/file/temporary_registry.h"
#include "isotope/error.h"
#include "isotope/extract.h"  // OptionError
#include "isotope/version.h"
#include "tools/commands.h"
#include "tools/support/command_line.h"
#include "tools/support/mpi_launcher.h"
#ifdef ISOTOPE_HAVE_MPI
#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "dist/mpi_module.h"
#include "tools/support/command_module.h"
#endif

// Under AddressSanitizer (CI): fontconfig, which PLplot's cairo driver reaches through pango
// for `sweep --plot`, keeps a process-lifetime cache that LeakSanitizer reports as leaked. It
// does not grow with the plots drawn. Unused in other builds.
extern "C" const char* __lsan_default_suppressions();
extern "C" const char* __lsan_default_suppressions() { return "leak:libfontconfig.so\n"; }

#ifdef ISOTOPE_HAVE_MPI
namespace {

// "" when every rank of WORLD was started with the same words as this one; otherwise what differs,
// for rank 0 to say. Every rank calls it (one all_gather).
std::string ranks_disagree(const isotope::Distribution& world, int argc, char** argv) {
  std::string words;
  for (int i = 1; i < argc; ++i) words += std::string(i > 1 ? " " : "") + argv[i];
  const std::vector<uint8_t> mine(words.begin(), words.end());
  const std::vector<std::vector<uint8_t>> all = world.all_gather(mine);
  for (size_t r = 1; r < all.size(); ++r)
    if (all[r] != all[0]) {
      auto shown = [](const std::vector<uint8_t>& w) {
        const std::string text(w.begin(), w.begin() + static_cast<std::ptrdiff_t>(std::min<size_t>(w.size(), 200)));
        return "'isotope " + text + (w.size() > 200 ? "...'" : "'");
      };
      return "the ranks of this job run different commands: rank 0 " + shown(all[0]) + ", rank " + std::to_string(r) +
             " " + shown(all[r]) + "; under mpirun every rank runs the same isotope command with the same options";
    }
  return "";
}

}  // namespace
#endif

int main(int argc, char** argv) {
  using namespace isotope::tools;
  // A file size limit (ulimit -f, a quota) would otherwise kill the process by SIGXFSZ halfway
  // through a write; ignored, the write fails with EFBIG and the output's own error path runs
  // (AtomicFile's: the message, the temporary removed, the target left as it was).
  std::signal(SIGXFSZ, SIG_IGN);
  const MpiLauncher launcher = mpi_launcher();
#ifdef ISOTOPE_HAVE_MPI
  // Started by mpirun (or srun): every rank runs the command, sharing its work
  // (docs/DISTRIBUTED.md); only rank 0 prints. Started otherwise: no MPI at all.
  std::unique_ptr<isotope::MpiRuntime> mpi;
  if (launcher.launched) {
    try {
      mpi.reset(module_function<isotope::StartMpi>(isotope::kMpiModule, isotope::kStartMpi)(&argc, &argv));
    } catch (const std::exception& e) {
      std::cerr << "isotope: error: " << e.what() << '\n';
      return 1;
    }
    set_process_group(&mpi->world());
    // Every rank must run the same command with the same options (an MPMD launch may give them
    // different ones): the ranks compare their words once, before any of them parses or reads, and
    // all stop with one message otherwise, rather than wait for each other forever or weld a mesh
    // of different isovalues.
    if (const std::string differ = ranks_disagree(mpi->world(), argc, argv); !differ.empty()) {
      if (mpi->world().rank() == 0) std::cerr << "isotope: usage error: " << differ << '\n';
      return 2;
    }
  }
#else
  // An MPI launcher started this isotope, built without MPI, as one of several ranks: each would run
  // the whole job alone, racing for the same outputs.
  if (launcher.launched && (launcher.ranks != 1 || launcher.rank != 0)) {
    std::cerr << "isotope: error: started by an MPI launcher as rank " << launcher.rank << " of "
              << (launcher.ranks > 0 ? std::to_string(launcher.ranks) : std::string("several"))
              << ", but this isotope was built without MPI, so every rank would do the whole job alone; build it "
                 "with MPI (Debian: apt-get install libopenmpi-dev openmpi-bin, then configure and build again; "
                 "docs/DISTRIBUTED.md), or run it without mpirun (started by a program that mpirun started: clear "
                 "the launcher's variables, OMPI_* and PMI*, for this isotope to run alone)\n";
    return 1;
  }
#endif
  // SIGTERM and Ctrl-C end the command at once, its temporary files removed first
  // (remove_temporaries_now): an output half written, a volume's hierarchy store being
  // written. Under mpirun, which ends the other ranks of a job one of whose ranks failed or was
  // killed with SIGTERM (then SIGKILL), a rank blocked in a collective could not unwind to its
  // destructors. A convert and the bench stop between steps instead, and unwind (InterruptGuard).
  for (int sig : {SIGTERM, SIGINT})
    std::signal(sig, [](int s) {
      isotope::remove_temporaries_now();
      _exit(128 + s);
    });
  const bool speaks = speaking_rank();
  CLI::App app{"isotope " ISOTOPE_VERSION_STRING
               ": multiresolution isosurface extraction with topology control\n"
               "(Gerstner & Pajarola, IEEE Visualization 2000)"};
  app.name("isotope");
  app.set_version_flag("--version", std::string("isotope ") + ISOTOPE_VERSION_STRING);
  app.require_subcommand(1);
  const Command extract = add_extract_command(app);
  const Command generate = add_generate_command(app);
  const Command convert = add_convert_command(app);
  const Command info = add_info_command(app);
  const Command verify = add_verify_command(app);
  const Command sweep = add_sweep_command(app);
  const Command bench = add_bench_command(app);
  const Command demo = add_demo_command(app);
  const Command serve = add_serve_command(app);
  app.footer("Run 'isotope COMMAND --help' for the options of a command.");
  app.failure_message([](const CLI::App*, const CLI::Error& e) {
    return std::string("isotope: usage error: ") + e.what() + "\nRun 'isotope --help' or 'isotope COMMAND --help'.\n";
  });

  try {
    app.parse(argc, argv);
    if (app.got_subcommand("extract")) return extract();
    if (app.got_subcommand("generate")) return generate();
    if (app.got_subcommand("convert")) return convert();
    if (app.got_subcommand("info")) return info();
    if (app.got_subcommand("verify")) return verify();
    if (app.got_subcommand("sweep")) return sweep();
    if (app.got_subcommand("bench")) return bench();
    if (app.got_subcommand("demo")) return demo();
    if (app.got_subcommand("serve")) return serve();
    return 2;  // unreachable: require_subcommand(1)
  } catch (const CLI::ParseError& e) {
    // Every rank of a group parses the same words: rank 0 speaks for all.
    const int code = speaks ? app.exit(e) : e.get_exit_code();  // prints help, version or the usage message
    return code == 0 ? 0 : 2;                // CLI11's own codes (105, 106, ...) are all usage errors here
  } catch (const isotope::OptionError& e) {  // the library's word for an option out of range
    if (speaks)
      std::cerr << "isotope: usage error: --" << e.option << ": " << e.message
                << "\nRun 'isotope --help' or 'isotope COMMAND --help'.\n";
    return 2;
  } catch (const isotope::DistributedError& e) {  // every rank throws it; rank 0 says it once
    if (speaks) std::cerr << "isotope: " << (e.usage_error ? "usage error: " : "error: ") << e.what() << '\n';
    return e.usage_error ? 2 : 1;
  } catch (const std::exception& e) {
    const std::string what = dynamic_cast<const std::bad_alloc*>(&e) ? "out of memory" : e.what();
#ifdef ISOTOPE_HAVE_MPI
    // Every failure one rank may meet alone is settled among the ranks (DistributedError above); one
    // that was not may leave the others waiting in a collective: end them all rather than hang.
    if (mpi && mpi->world().ranks() > 1) {
      std::cerr << "isotope: error: rank " << mpi->world().rank() << " of " << mpi->world().ranks() << ": " << what
                << '\n';
      isotope::remove_temporaries_now();
      mpi->abort(1);
    }
#endif
    if (speaks) std::cerr << "isotope: error: " << what << '\n';
    return 1;
  }
}

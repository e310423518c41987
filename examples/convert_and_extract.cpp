// Out of core: a volume converted once into a store, within a memory budget, then extracted from
// the store, which reads only the bricks the surface reaches. Progress on stderr; Ctrl-C (or
// --stop-at FRACTION, to try it) cancels the convert, which then leaves no store behind.
//
//   convert_and_extract VOLUME STORE ISO MESH [EPS] [--stop-at FRACTION]
//
// VOLUME is anything isotope reads (NAME_XxYxZ_TYPE.raw, FILE.h5:/dataset, .nrrd, a TIFF stack).
// MESH's extension chooses its format (.ply, .obj, .stl, .glb, .vtp).
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include <isotope/isotope.h>

namespace {

std::atomic<bool> stop{false};  // set by Ctrl-C or --stop-at; read by convert and extract

extern "C" void on_interrupt(int) { stop.store(true); }

}  // namespace

// Whether TEXT is a number, into OUT.
bool number(const char* text, double& out) {
  char* end = nullptr;
  out = std::strtod(text, &end);
  return end != text && *end == '\0';
}

int main(int argc, char** argv) {
  double iso = 0, eps = 0, stop_at = 2;  // past 1: never stopped
  bool usable = argc >= 5 && number(argv[3], iso);
  for (int i = 5; usable && i < argc; ++i) {
    if (std::strcmp(argv[i], "--stop-at") == 0)
      usable = ++i < argc && number(argv[i], stop_at);
    else
      usable = number(argv[i], eps);
  }
  if (!usable) {
    std::fprintf(stderr, "usage: convert_and_extract VOLUME STORE ISO MESH [EPS] [--stop-at FRACTION]\n");
    return 2;
  }
  std::signal(SIGINT, on_interrupt);
  try {
    isotope::ConvertOptions c;
    c.memory_mb = 64;         // what the convert may hold, whatever the volume's size; the rest goes to disk
    isotope::RunContext run;  // how the calls run: the same bytes whatever it says
    run.cancel = &stop;       // Ctrl-C stops the convert (no store left) and the extraction
    int shown = -1;
    run.progress = [&](double fraction) {  // called at most once per percent, one call at a time; shown every 10%
      if (static_cast<int>(fraction * 10) > shown) {
        shown = static_cast<int>(fraction * 10);
        std::fprintf(stderr, "convert: %3.0f%%\n", 100 * fraction);
      }
      if (fraction >= stop_at) stop.store(true);
    };
    const isotope::ConvertStats converted = isotope::convert({argv[1]}, argv[2], c, run);
    std::printf("%s: %lld bricks, %.1f MB from %.1f MB\n", argv[2], static_cast<long long>(converted.bricks),
                converted.output_bytes / 1e6, converted.input_bytes / 1e6);

    isotope::Source store = isotope::open_volume({argv[2]});
    isotope::ExtractOptions o;
    o.iso = static_cast<float>(iso);
    o.eps = eps;             // data units; 0: full resolution
    run.progress = nullptr;  // a store's hierarchy is built: nothing to hear
    isotope::ExtractStats stats;
    const isotope::Mesh mesh = store.extract(o, run, &stats);  // isotope::ExtractionCancelled on Ctrl-C
    isotope::write_mesh(mesh, argv[4]);
    std::printf("%s: %zu triangles in %.3f s, %llu bytes of the store read\n", argv[4], mesh.triangles.size(),
                stats.seconds, static_cast<unsigned long long>(store.info().bytes_read));
  } catch (const isotope::ExtractionCancelled&) {
    std::fprintf(stderr, "convert_and_extract: extraction cancelled\n");
    return 1;
  } catch (const std::exception& e) {  // IoError("interrupted") for a cancelled convert: no store left
    std::fprintf(stderr, "convert_and_extract: %s\n", e.what());
    return 1;
  }
}

// Line plots (write_line_plot_png): a PNG of the requested size, log axes that survive eps = 0,
// atomic replacement, concurrent callers, no output on the terminal, and PLplot's fatal errors
// turned into IoError instead of exit().
#include "tools/support/line_plot.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "isotope/error.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

// LeakSanitizer (the ASan CI run) reports fontconfig patterns that pango caches for the text of
// PLplot's cairo driver and never frees: a bounded cache inside libfontconfig (every leaked block
// is allocated there), not a leak of ours. Read by LSan only, ignored in other builds.
extern "C" const char* __lsan_default_suppressions() { return "leak:libfontconfig.so\n"; }

namespace isotope {
namespace {

namespace fs = std::filesystem;

using testing::Bytes;
using testing::io_error_of;
using testing::read_bytes;
using LinePlotPng = testing::TempDirTest;

constexpr unsigned char kPngSignature[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

bool is_png(const Bytes& b) {
  return b.size() > 24 && std::equal(std::begin(kPngSignature), std::end(kPngSignature), b.begin());
}

uint32_t big_endian_u32(const Bytes& b, size_t at) {
  return uint32_t{b[at]} << 24 | uint32_t{b[at + 1]} << 16 | uint32_t{b[at + 2]} << 8 | uint32_t{b[at + 3]};
}

// The first chunk of a PNG is IHDR: width and height, big-endian, at bytes 16 and 20.
void expect_png_of_size(const Bytes& b, int width, int height) {
  ASSERT_TRUE(is_png(b)) << b.size() << " bytes, no PNG signature";
  EXPECT_EQ(std::string(b.begin() + 12, b.begin() + 16), "IHDR");
  EXPECT_EQ(big_endian_u32(b, 16), static_cast<uint32_t>(width));
  EXPECT_EQ(big_endian_u32(b, 20), static_cast<uint32_t>(height));
}

// Triangles falling with eps for the topology modes, as `isotope sweep` will plot them; eps = 0
// first, which a log eps axis cannot show.
LinePlot sweep_plot() {
  LinePlot plot;
  plot.title = "Triangles against eps";
  plot.x_label = "eps";
  plot.y_label = "triangles";
  plot.log_x = plot.log_y = true;
  const std::vector<double> eps{0, 0.001, 0.01, 0.1, 1, 10};
  const std::vector<std::pair<std::string, double>> modes{
      {"none", 200}, {"preserve", 3000}, {"simplify delta=0.1", 1200}, {"simplify delta=1", 500}};
  for (const auto& [label, floor] : modes) {
    PlotSeries s{label, {}, {}};
    for (double e : eps) {
      s.x.push_back(e);
      s.y.push_back(std::round(floor + 120000 / (1 + e / 0.01)));
    }
    plot.series.push_back(s);
  }
  return plot;
}

TEST_F(LinePlotPng, WritesPngWithTheRequestedSize) {
  const LinePlot plot = sweep_plot();
  write_line_plot_png(plot, path("default.png"));
  expect_png_of_size(read_bytes(path("default.png")), 1200, 800);

  LinePlot small = plot;
  small.width = 640;
  small.height = 480;
  write_line_plot_png(small, path("small.png"));
  expect_png_of_size(read_bytes(path("small.png")), 640, 480);
  EXPECT_EQ(entries(), (std::vector<std::string>{"default.png", "small.png"}));
}

TEST_F(LinePlotPng, LogAxesLeaveOutPointsTheyCannotShow) {
  LinePlot plot = sweep_plot();  // eps = 0 on a log x axis
  const double nan = std::numeric_limits<double>::quiet_NaN();
  plot.series.push_back({"zero triangles, a gap", {0.001, 0.01, 0.1, 1}, {100, 0, nan, 50}});
  write_line_plot_png(plot, path("gaps.png"));
  expect_png_of_size(read_bytes(path("gaps.png")), 1200, 800);

  // Nothing left to draw at all still gives axes, a title and a legend.
  LinePlot only_zero;
  only_zero.log_x = true;
  only_zero.series.push_back({"eps = 0 only", {0, 0}, {10, 20}});
  write_line_plot_png(only_zero, path("only_zero.png"));
  expect_png_of_size(read_bytes(path("only_zero.png")), 1200, 800);
}

TEST_F(LinePlotPng, SamePlotSameBytesDifferentPlotDifferentBytes) {
  const LinePlot plot = sweep_plot();
  write_line_plot_png(plot, path("a.png"));
  write_line_plot_png(plot, path("b.png"));
  LinePlot other = plot;
  other.series[1].y[3] *= 2;
  write_line_plot_png(other, path("c.png"));
  LinePlot linear = plot;
  linear.log_x = linear.log_y = false;
  linear.title = "Linear axes, # kept";
  write_line_plot_png(linear, path("d.png"));

  const Bytes a = read_bytes(path("a.png"));
  EXPECT_EQ(a, read_bytes(path("b.png")));
  EXPECT_NE(a, read_bytes(path("c.png")));
  EXPECT_NE(a, read_bytes(path("d.png")));
}

TEST_F(LinePlotPng, MissingDirectoryIsAnIoErrorAndLeavesNothing) {
  const std::string target = path("missing/plot.png");
  const std::string message = io_error_of([&] { write_line_plot_png(sweep_plot(), target); });
  EXPECT_CONTAINS(message, target);
  EXPECT_CONTAINS(message, "does not exist");
  EXPECT_TRUE(entries().empty());
}

TEST_F(LinePlotPng, ExistingFileIsReplacedOnlyOnSuccess) {
  const std::string target = path("plot.png");
  testing::write_file(target, "an older plot");

  LinePlot malformed = sweep_plot();
  malformed.series[2].y.pop_back();
  const std::string message = io_error_of([&] { write_line_plot_png(malformed, target); });
  EXPECT_CONTAINS(message, target);
  EXPECT_CONTAINS(message, "series 'simplify delta=0.1' has 6 x values but 5 y values");
  const Bytes old = read_bytes(target);
  EXPECT_EQ(std::string(old.begin(), old.end()), "an older plot");
  EXPECT_EQ(entries(), std::vector<std::string>{"plot.png"});

  write_line_plot_png(sweep_plot(), target);
  expect_png_of_size(read_bytes(target), 1200, 800);
  EXPECT_EQ(entries(), std::vector<std::string>{"plot.png"});  // no temporary left beside it
}

TEST_F(LinePlotPng, ImageSizeOutOfRangeIsAnIoError) {
  LinePlot plot = sweep_plot();
  plot.width = 10;
  EXPECT_CONTAINS(io_error_of([&] { write_line_plot_png(plot, path("tiny.png")); }), "image size 10x800");
  plot.width = 1200;
  plot.height = 100000;
  EXPECT_CONTAINS(io_error_of([&] { write_line_plot_png(plot, path("huge.png")); }), "image size 1200x100000");
  EXPECT_TRUE(entries().empty());
}

TEST_F(LinePlotPng, PrintsNothing) {
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  write_line_plot_png(sweep_plot(), path("quiet.png"));
  LinePlot linear = sweep_plot();
  linear.log_x = linear.log_y = false;
  write_line_plot_png(linear, path("quiet_linear.png"));
  std::fflush(nullptr);
  const std::string out = ::testing::internal::GetCapturedStdout();
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(out, "");
  EXPECT_EQ(err, "");
  expect_png_of_size(read_bytes(path("quiet.png")), 1200, 800);
}

TEST_F(LinePlotPng, ConcurrentCallersGetTheSerialImages) {
  constexpr int kThreads = 4, kPlotsEach = 3;
  std::vector<LinePlot> plots;
  for (int i = 0; i < kThreads; ++i) {
    LinePlot plot = sweep_plot();
    plot.title += " " + std::to_string(i);
    plot.log_y = i % 2 == 0;
    plots.push_back(plot);
    write_line_plot_png(plot, path("serial" + std::to_string(i) + ".png"));
  }
  std::vector<std::thread> threads;
  for (int i = 0; i < kThreads; ++i) {
    threads.emplace_back([&, i] {
      for (int k = 0; k < kPlotsEach; ++k)
        write_line_plot_png(plots[i], path("thread" + std::to_string(i) + "_" + std::to_string(k) + ".png"));
    });
  }
  for (std::thread& t : threads) t.join();
  for (int i = 0; i < kThreads; ++i) {
    const Bytes serial = read_bytes(path("serial" + std::to_string(i) + ".png"));
    ASSERT_TRUE(is_png(serial));
    for (int k = 0; k < kPlotsEach; ++k)
      EXPECT_EQ(read_bytes(path("thread" + std::to_string(i) + "_" + std::to_string(k) + ".png")), serial)
          << "thread " << i << ", plot " << k;
  }
}

// PLplot's failures are process-wide (its driver table is loaded once), so each runs in a fresh
// process: the "threadsafe" death-test style re-executes this binary for the one test. The child
// reports what it caught and leaves by _Exit, so an exit() inside PLplot would show as a wrong
// exit code and a missing report.
void expect_in_fresh_process(const std::function<int()>& child, const std::string& report) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        const int code = child();
        std::fflush(nullptr);
        std::_Exit(code);
      },
      ::testing::ExitedWithCode(0), report);
}

// Writes into a fresh directory with PLplot's drivers taken from `drivers`; 0 when every call
// threw an IoError (reported on stderr as "caught: ...") and left the directory empty.
int plot_with_drivers(const fs::path& drivers, const fs::path& out_dir, int calls) {
  setenv("PLPLOT_DRV_DIR", drivers.c_str(), 1);
  fs::create_directories(out_dir);
  int failures = 0;
  for (int i = 0; i < calls; ++i) {
    try {
      write_line_plot_png(sweep_plot(), (out_dir / "plot.png").string());
      ++failures;
    } catch (const IoError& e) {
      std::fprintf(stderr, "caught: %s\n", e.what());
    }
  }
  if (!fs::is_empty(out_dir)) ++failures;
  std::error_code ec;
  fs::remove_all(out_dir.parent_path(), ec);  // the fixture's TearDown does not run in the child
  return failures;
}

TEST_F(LinePlotPng, MissingPngDriverIsAnIoError) {
  const fs::path drivers = dir_ / "drivers";
  expect_in_fresh_process(
      [&] {
        // Only PLplot's null device, as when plplot-driver-cairo is not installed.
        fs::create_directories(drivers);
        testing::write_file((drivers / "null.driver_info").string(), "null:Null device:-1:null:42:null\n");
        return plot_with_drivers(drivers, dir_ / "out", 1);
      },
      "caught: .*plot.png.*no pngcairo device \\(install plplot-driver-cairo\\)");
}

TEST_F(LinePlotPng, PLplotFatalErrorIsAnIoErrorNotAnExit) {
  const fs::path drivers = dir_ / "drivers";
  expect_in_fresh_process(
      [&] {
        // A pngcairo device whose driver cannot be loaded: PLplot calls plexit().
        fs::create_directories(drivers);
        testing::write_file((drivers / "cairo.driver_info").string(),
                            "pngcairo:Cairo PNG Driver:0:cairo:105:pngcairo\n");
        testing::write_file((drivers / "cairo.so").string(), "not a shared object");
        return plot_with_drivers(drivers, dir_ / "out", 2);
      },
      "caught: .*PLplot failed \\(Unable to load driver.*\n"
      "caught: .*PLplot failed .*is not used again in this process");
}

}  // namespace
}  // namespace isotope

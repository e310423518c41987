#pragma once
// Line plots as PNG images (PLplot's pngcairo device, no display needed): a sweep's result, such
// as triangles against eps for each topology mode, one coloured and marked curve per series.
#include <string>
#include <vector>

namespace isotope {

struct PlotSeries {
  std::string label;         // legend text
  std::vector<double> x, y;  // as many x as y; joined in this order
};

struct LinePlot {
  std::string title, x_label, y_label;
  // A log axis has a labelled tick and a grid line at every decade, at least two of them in view.
  // A point that cannot sit on it (x <= 0 on a log x axis, y <= 0 on a log y axis) is left out,
  // as is any non-finite point, and its curve is broken there: eps = 0 simply has no marker on a
  // log eps axis. A caller that wants it shown maps it to a small positive eps of its choice.
  bool log_x = false, log_y = false;
  std::vector<PlotSeries> series;  // each its own colour and marker, in order, with a legend entry
  int width = 1200, height = 800;  // pixels, 200..8000 each
};

// Draws `plot` and writes it to `path` as a PNG image, atomically (AtomicFile): `path` is
// replaced only by a complete image. Throws IoError naming `path` when the plot is malformed (x
// and y of different lengths, a size out of range), the directory is missing or not writable,
// the disk is full, or PLplot fails (e.g. plplot-driver-cairo not installed). Safe to call from
// several threads: PLplot's global state is behind one lock, so plots are drawn one at a time.
// Prints nothing.
void write_line_plot_png(const LinePlot& plot, const std::string& path);

}  // namespace isotope

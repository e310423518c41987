#include <plplot.h>
#include <sys/types.h>  // ssize_t of fopencookie's callbacks

#include <algorithm>
#include <array>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "isotope/error.h"
#include "tools/support/line_plot_module.h"

// PLplot keeps its streams, error handlers and driver table in globals and reports a fatal
// error by calling exit(). So every call here holds one lock, draws on a stream of its own
// (plmkstrm .. plend1), renders into memory through a stdio stream of ours, and turns PLplot's
// two error paths into an IoError:
//   plabort (a drawing call refused, the stream goes on): recorded through plsError, which
//     also keeps PLplot from printing it; checked once the page is done.
//   plexit (PLplot gives up, normally exit()): our exit handler longjmps back to the guard
//     around the drawing code, which therefore holds no object with a destructor. The stream is
//     then in an unknown state, so later calls refuse at once instead of touching PLplot again.
// This file is the plot module (one of the command's modules): the command writes the PNG bytes
// with AtomicFile, which sees every write and flush error; the pngcairo driver itself ignores them.

namespace isotope {
namespace {

// ---- What a plot looks like --------------------------------------------------------------

struct Rgb {
  PLINT r, g, b;
};

// cmap0: background, ink (frame, text), grid, then the series' colours (Tableau 10).
constexpr PLINT kInk = 1, kGrid = 2, kFirstSeriesColour = 3;
constexpr std::array<Rgb, 3> kFixedColours{{{255, 255, 255}, {0, 0, 0}, {218, 218, 218}}};
constexpr std::array<Rgb, 10> kSeriesColours{{{31, 119, 180},
                                              {255, 127, 14},
                                              {44, 160, 44},
                                              {214, 39, 40},
                                              {148, 103, 189},
                                              {140, 86, 75},
                                              {227, 119, 194},
                                              {127, 127, 127},
                                              {188, 189, 34},
                                              {23, 190, 207}}};
// UTF-8 glyphs drawn centred on each point (DejaVu Sans has all of them).
constexpr std::array<const char*, 6> kMarkers{"\u25CF", "\u25A0", "\u25B2", "\u25C6", "\u25BC", "\u2605"};

constexpr int kMinSide = 200, kMaxSide = 8000;
constexpr double kTextScale = 1.15, kTitleScale = 1.35, kMarkerScale = 0.85, kLegendTextScale = 0.95;
constexpr double kLineWidth = 2.5;
// Where the axis labels and the title sit, in character heights off the frame (PLplot scales
// text with the image, so the margins follow the text rather than the image).
constexpr double kXLabelOffset = 3.0, kYLabelOffsetLog = 4.0, kYLabelOffsetLinear = 5.0, kTitleOffset = 1.1;
constexpr double kMarginRight = 2.2;
constexpr double kAxisPad = 0.03;  // fraction of an axis' span left free beyond the data at each end

// ---- Preparation: plain C++, before PLplot is touched ------------------------------------

// PLplot reads '#' as its escape character; doubled, it prints one.
std::string escape_text(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    out += c;
    if (c == '#') out += '#';
  }
  return out;
}

struct Range {
  double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
  bool empty() const { return !(lo <= hi); }
  void add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

// In plot coordinates (log10 of the value on a log axis): a small margin beyond the data so no
// marker sits on the frame, a unit-sized window around a single value, and on a log axis at
// least two decades inside, since only decades are labelled there.
Range axis_window(Range r, bool log) {
  if (r.empty()) return {0, 1};
  if (r.lo == r.hi) {
    const double half = log || r.lo == 0 ? 1.0 : std::abs(r.lo) * 0.1;
    return {r.lo - half, r.hi + half};
  }
  const double pad = (r.hi - r.lo) * kAxisPad;
  Range w{r.lo - pad, r.hi + pad};
  if (log && std::floor(w.hi) - std::ceil(w.lo) < 1) w = {std::floor(w.lo), std::ceil(w.hi)};
  return w;
}

struct PreparedSeries {
  std::string label;
  std::vector<PLFLT> x, y;      // kept points in plot coordinates
  std::vector<PLINT> run_ends;  // exclusive end of each unbroken run of x, y
};

struct Prepared {
  std::string title, x_label, y_label;
  std::vector<PreparedSeries> series;
  Range x, y;  // the axes' windows in plot coordinates
  PLINT legend_position = PL_POSITION_TOP | PL_POSITION_RIGHT;
};

std::string describe(const std::string& path, const LinePlot& plot) {
  return path + ": line plot" + (plot.title.empty() ? std::string() : " '" + plot.title + "'");
}

// The corner of the plot that the curves cross least, where the legend hides the least: each
// corner counts the points and samples along the lines that fall in it.
PLINT quietest_corner(const Prepared& p) {
  constexpr std::array<PLINT, 4> kCorners{PL_POSITION_TOP | PL_POSITION_RIGHT, PL_POSITION_TOP | PL_POSITION_LEFT,
                                          PL_POSITION_BOTTOM | PL_POSITION_RIGHT,
                                          PL_POSITION_BOTTOM | PL_POSITION_LEFT};
  constexpr int kSamplesPerSegment = 8;
  std::array<size_t, 4> count{};
  const auto add = [&](double x, double y) {
    const double u = (x - p.x.lo) / (p.x.hi - p.x.lo), v = (y - p.y.lo) / (p.y.hi - p.y.lo);
    const bool right = u > 0.55, left = u<0.45, top = v> 0.6, bottom = v < 0.4;
    count[0] += right && top;
    count[1] += left && top;
    count[2] += right && bottom;
    count[3] += left && bottom;
  };
  for (const PreparedSeries& s : p.series) {
    size_t begin = 0;
    for (const PLINT end : s.run_ends) {
      for (size_t i = begin; i < static_cast<size_t>(end); ++i) {
        add(s.x[i], s.y[i]);
        if (i + 1 == static_cast<size_t>(end)) break;
        for (int k = 1; k < kSamplesPerSegment; ++k) {
          const double t = static_cast<double>(k) / kSamplesPerSegment;
          add(s.x[i] + t * (s.x[i + 1] - s.x[i]), s.y[i] + t * (s.y[i + 1] - s.y[i]));
        }
      }
      begin = static_cast<size_t>(end);
    }
  }
  return kCorners[static_cast<size_t>(std::min_element(count.begin(), count.end()) - count.begin())];
}

Prepared prepare(const LinePlot& plot, const std::string& path) {
  for (const int side : {plot.width, plot.height}) {
    if (side < kMinSide || side > kMaxSide) {
      throw IoError(describe(path, plot) + ": image size " + std::to_string(plot.width) + "x" +
                    std::to_string(plot.height) + " is outside " + std::to_string(kMinSide) + ".." +
                    std::to_string(kMaxSide) + " pixels a side");
    }
  }
  Prepared p;
  p.title = escape_text(plot.title);
  p.x_label = escape_text(plot.x_label);
  p.y_label = escape_text(plot.y_label);
  Range x, y;
  for (const PlotSeries& in : plot.series) {
    if (in.x.size() != in.y.size()) {
      throw IoError(describe(path, plot) + ": series '" + in.label + "' has " + std::to_string(in.x.size()) +
                    " x values but " + std::to_string(in.y.size()) + " y values");
    }
    PreparedSeries s;
    s.label = escape_text(in.label);
    for (size_t i = 0; i < in.x.size(); ++i) {
      const bool drawable = std::isfinite(in.x[i]) && std::isfinite(in.y[i]) && (!plot.log_x || in.x[i] > 0) &&
                            (!plot.log_y || in.y[i] > 0);
      if (!drawable) {
        if (s.run_ends.empty() || s.run_ends.back() != static_cast<PLINT>(s.x.size()))
          s.run_ends.push_back(static_cast<PLINT>(s.x.size()));
        continue;
      }
      s.x.push_back(plot.log_x ? std::log10(in.x[i]) : in.x[i]);
      s.y.push_back(plot.log_y ? std::log10(in.y[i]) : in.y[i]);
      x.add(s.x.back());
      y.add(s.y.back());
    }
    s.run_ends.push_back(static_cast<PLINT>(s.x.size()));
    p.series.push_back(std::move(s));
  }
  p.x = axis_window(x, plot.log_x);
  p.y = axis_window(y, plot.log_y);
  p.legend_position = quietest_corner(p);
  return p;
}

// ---- Rendering: PLplot calls only ---------------------------------------------------------
// Everything from here to the guard may be left by longjmp, so it holds no object with a
// destructor: the scene is plain pointers into a Prepared and arrays that outlive the call.

struct SeriesView {
  const PLFLT* x;
  const PLFLT* y;
  const PLINT* run_ends;
  PLINT runs;
  PLINT colour;
  const char* marker;
};

struct Legend {
  PLINT entries;
  PLINT position;
  const PLINT* opts;
  const char* const* text;
  const PLINT* text_colours;
  const PLINT* line_colours;
  const PLINT* line_styles;
  const PLFLT* line_widths;
  const PLINT* symbol_colours;
  const PLFLT* symbol_scales;
  const PLINT* symbol_numbers;
  const char* const* symbols;
};

struct Scene {
  const char* title;
  const char* x_label;
  const char* y_label;
  PLINT width, height;
  bool log_x, log_y;
  PLFLT x0, x1, y0, y1;
  const SeriesView* series;
  PLINT n_series;
  Legend legend;
  std::FILE* out;
};

enum class Outcome { kDrawn, kNoDevice };

// Lives only while the lock is held.
std::jmp_buf g_exit_jump;
char g_exit_message[1024];
PLINT g_abort_code = 0;
char g_abort_message[4096];  // plabort sprintf()s into it: PLplot's messages are far shorter

int jump_out_of_plexit(const char* message) {
  std::snprintf(g_exit_message, sizeof g_exit_message, "%s", message != nullptr ? message : "");
  std::longjmp(g_exit_jump, 1);
}

bool has_png_device() {
  // plgFileDevs fills arrays the caller provides; PLplot has a few dozen devices at most.
  static const char* menus[128];
  static const char* names[128];
  const char** menu_ptr = menus;
  const char** name_ptr = names;
  int n = 128;
  plgFileDevs(&menu_ptr, &name_ptr, &n);
  for (int i = 0; i < n; ++i)
    if (name_ptr[i] != nullptr && std::strcmp(name_ptr[i], "pngcairo") == 0) return true;
  return false;
}

void draw_axes(const Scene& s) {
  plschr(0.0, kTextScale);
  PLFLT default_height = 0, height = 0, page_x0 = 0, page_x1 = 0, page_y0 = 0, page_y1 = 0;
  plgchr(&default_height, &height);  // mm
  plgspa(&page_x0, &page_x1, &page_y0, &page_y1);
  const PLFLT y_label_offset = s.log_y ? kYLabelOffsetLog : kYLabelOffsetLinear;
  const PLFLT top = (kTitleOffset + 1.2) * kTitleScale / kTextScale * height;
  plsvpa((y_label_offset + 1.3) * height, page_x1 - page_x0 - kMarginRight * height, (kXLabelOffset + 1.4) * height,
         page_y1 - page_y0 - top);
  plwind(s.x0, s.x1, s.y0, s.y1);
  // Grid first so the curves and the frame are drawn over it.
  plcol0(kGrid);
  plwidth(1.0);
  plbox(s.log_x ? "gl" : "g", 0.0, 0, s.log_y ? "gl" : "g", 0.0, 0);
  plcol0(kInk);
  plwidth(1.5);
  // b,c: frame; n: labels below/left; t,s: major and minor ticks; l: log; v: upright y labels.
  plbox(s.log_x ? "bcnstl" : "bcnst", 0.0, 0, s.log_y ? "bcnstvl" : "bcnstv", 0.0, 0);
  plmtex("b", kXLabelOffset, 0.5, 0.5, s.x_label);
  plmtex("l", y_label_offset, 0.5, 0.5, s.y_label);
  plschr(0.0, kTitleScale);
  plmtex("t", kTitleOffset, 0.5, 0.5, s.title);
}

void draw_series(const Scene& s) {
  for (PLINT k = 0; k < s.n_series; ++k) {
    const SeriesView& v = s.series[k];
    plcol0(v.colour);
    plwidth(kLineWidth);
    PLINT begin = 0;
    for (PLINT r = 0; r < v.runs; ++r) {
      const PLINT end = v.run_ends[r];
      if (end - begin >= 2) plline(end - begin, v.x + begin, v.y + begin);
      begin = end;
    }
    plschr(0.0, kMarkerScale);
    if (begin > 0) plstring(begin, v.x, v.y, v.marker);
  }
}

void draw_legend(const Scene& s) {
  if (s.legend.entries == 0) return;
  const Legend& l = s.legend;
  PLFLT width = 0, height = 0;
  plschr(0.0, kLegendTextScale);
  pllegend(&width, &height, PL_LEGEND_BACKGROUND | PL_LEGEND_BOUNDING_BOX, l.position | PL_POSITION_INSIDE, 0.02, 0.03,
           0.07, 0, kInk, 1, 0, 0, l.entries, l.opts, 0.6, 1.0, 2.0, 0.0, l.text_colours, l.text, nullptr, nullptr,
           nullptr, nullptr, l.line_colours, l.line_styles, l.line_widths, l.symbol_colours, l.symbol_scales,
           l.symbol_numbers, l.symbols);
}

// One page on a stream of its own; plend1 writes the PNG into s.out and closes it.
Outcome draw(const Scene& s) {
  // Error reports of the streams this code makes current go to our buffers, not to stderr.
  plsError(&g_abort_code, g_abort_message);
  PLINT stream = 0;
  plmkstrm(&stream);
  plsError(&g_abort_code, g_abort_message);
  if (!has_png_device()) {
    plend1();
    return Outcome::kNoDevice;
  }
  plsdev("pngcairo");
  plsfile(s.out);
  plspage(0.0, 0.0, s.width, s.height, 0, 0);
  plspause(0);
  std::array<PLINT, kFixedColours.size() + kSeriesColours.size()> r{}, g{}, b{};
  for (size_t i = 0; i < r.size(); ++i) {
    const Rgb& c = i < kFixedColours.size() ? kFixedColours[i] : kSeriesColours[i - kFixedColours.size()];
    r[i] = c.r;
    g[i] = c.g;
    b[i] = c.b;
  }
  plscmap0(r.data(), g.data(), b.data(), static_cast<PLINT>(r.size()));
  plinit();
  pladv(0);
  draw_axes(s);
  draw_series(s);
  draw_legend(s);
  plend1();
  return Outcome::kDrawn;
}

// The only place PLplot's exit handler returns to. False when PLplot gave up.
bool draw_guarded(const Scene& s, Outcome* outcome) {
  plsexit(jump_out_of_plexit);
  if (setjmp(g_exit_jump) != 0) return false;
  *outcome = draw(s);
  return true;
}

// ---- The memory stream PLplot writes the PNG into ------------------------------------------

struct Sink {
  std::vector<unsigned char> bytes;
  bool out_of_memory = false;
  bool closed = false;
};

ssize_t sink_write(void* cookie, const char* data, size_t size) {
  Sink* sink = static_cast<Sink*>(cookie);
  try {
    sink->bytes.insert(sink->bytes.end(), data, data + size);
  } catch (const std::bad_alloc&) {
    sink->out_of_memory = true;
    return 0;
  }
  return static_cast<ssize_t>(size);
}

int sink_close(void* cookie) {
  static_cast<Sink*>(cookie)->closed = true;
  return 0;
}

// PLplot's messages come with newlines around them.
std::string trimmed(const char* message) {
  std::string text = message;
  const size_t begin = text.find_first_not_of(" \n");
  if (begin == std::string::npos) return "no message";
  return text.substr(begin, text.find_last_not_of(" \n") + 1 - begin);
}

std::mutex g_plplot_mutex;
std::string g_plplot_broken;  // why PLplot may not be used again in this process

std::vector<unsigned char> render_png(const LinePlot& plot, const Prepared& p, const std::string& path) {
  const size_t n = p.series.size();
  std::vector<SeriesView> views(n);
  std::vector<PLINT> opts(n, PL_LEGEND_LINE | PL_LEGEND_SYMBOL), text_colours(n, kInk), colours(n), line_styles(n, 1),
      symbol_numbers(n, 1);
  std::vector<PLFLT> line_widths(n, kLineWidth), symbol_scales(n, 1.0);
  std::vector<const char*> text(n), symbols(n);
  for (size_t i = 0; i < n; ++i) {
    const PreparedSeries& s = p.series[i];
    colours[i] = kFirstSeriesColour + static_cast<PLINT>(i % kSeriesColours.size());
    symbols[i] = kMarkers[i % kMarkers.size()];
    text[i] = s.label.c_str();
    views[i] = {s.x.data(), s.y.data(), s.run_ends.data(), static_cast<PLINT>(s.run_ends.size()),
                colours[i], symbols[i]};
  }
  Scene scene{p.title.c_str(),
              p.x_label.c_str(),
              p.y_label.c_str(),
              plot.width,
              plot.height,
              plot.log_x,
              plot.log_y,
              p.x.lo,
              p.x.hi,
              p.y.lo,
              p.y.hi,
              views.data(),
              static_cast<PLINT>(n),
              Legend{static_cast<PLINT>(n), p.legend_position, opts.data(), text.data(), text_colours.data(),
                     colours.data(), line_styles.data(), line_widths.data(), colours.data(), symbol_scales.data(),
                     symbol_numbers.data(), symbols.data()},
              nullptr};

  Sink sink;
  std::lock_guard<std::mutex> lock(g_plplot_mutex);
  if (!g_plplot_broken.empty()) throw IoError(describe(path, plot) + ": " + g_plplot_broken);
  scene.out = fopencookie(&sink, "wb", cookie_io_functions_t{nullptr, sink_write, nullptr, sink_close});
  if (scene.out == nullptr) throw IoError(describe(path, plot) + ": cannot open a memory stream for PLplot");
  g_abort_code = 0;
  g_abort_message[0] = '\0';
  Outcome outcome = Outcome::kDrawn;
  const bool finished = draw_guarded(scene, &outcome);
  plsexit(nullptr);  // g_exit_jump is stale from here on
  // plend1 closes the stream; when PLplot stopped short of it, it is ours to close.
  if (!sink.closed) std::fclose(scene.out);
  if (!finished) {
    g_plplot_broken = "PLplot failed (" + trimmed(g_exit_message) +
                      "; is plplot-driver-cairo installed correctly?) and is not used again in this process";
    throw IoError(describe(path, plot) + ": " + g_plplot_broken);
  }
  if (outcome == Outcome::kNoDevice)
    throw IoError(describe(path, plot) + ": PLplot has no pngcairo device (install plplot-driver-cairo)");
  if (g_abort_code != 0) throw IoError(describe(path, plot) + ": PLplot: " + trimmed(g_abort_message));
  if (sink.out_of_memory) throw IoError(describe(path, plot) + ": out of memory while encoding the PNG image");
  static constexpr unsigned char kPngSignature[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (sink.bytes.size() < sizeof kPngSignature ||
      std::memcmp(sink.bytes.data(), kPngSignature, sizeof kPngSignature) != 0)
    throw IoError(describe(path, plot) + ": PLplot's pngcairo device produced no PNG image");
  return std::move(sink.bytes);
}

}  // namespace

extern "C" void isotope_render_line_plot(const LinePlot& plot, const std::string& path,
                                         std::vector<unsigned char>& png) {
  png = render_png(plot, prepare(plot, path), path);
}

}  // namespace isotope

#pragma once
// The plot module's entry point (one of the command's modules, module_function): PLplot is loaded only by the
// commands that draw.
#include <string>
#include <vector>

#include "tools/support/line_plot.h"

namespace isotope {

inline constexpr const char* kPlotModule = "isotope-plot";
inline constexpr const char* kRenderLinePlot = "isotope_render_line_plot";
// The PNG image of `plot`; throws IoError naming `path` (write_line_plot_png's errors but the file's).
extern "C" void isotope_render_line_plot(const LinePlot& plot, const std::string& path,
                                         std::vector<unsigned char>& png);
using RenderLinePlot = decltype(isotope_render_line_plot);

}  // namespace isotope

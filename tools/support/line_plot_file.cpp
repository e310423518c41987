// write_line_plot_png: the image drawn by the plot module, written atomically by the command.
#include <string>
#include <vector>

#include "io/file/atomic_file.h"
#include "tools/support/command_module.h"
#include "tools/support/line_plot.h"
#include "tools/support/line_plot_module.h"

namespace isotope {

void write_line_plot_png(const LinePlot& plot, const std::string& path) {
  AtomicFile out(path);  // before drawing: a missing or read-only directory fails fast
  std::vector<unsigned char> png;
  tools::module_function<RenderLinePlot>(kPlotModule, kRenderLinePlot)(plot, path, png);
  out.write(png.data(), png.size());
  out.commit();
}

}  // namespace isotope

#include "tools/support/command_module.h"

#include <dlfcn.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <system_error>

#include "isotope/error.h"

namespace isotope::tools {

std::string module_folder() {
  std::error_code error;
  const std::filesystem::path program = std::filesystem::read_symlink("/proc/self/exe", error);
  if (error) throw IoError("cannot find the running program's path (/proc/self/exe): " + error.message());
  return (program.parent_path() / ISOTOPE_MODULE_DIR).lexically_normal().string();
}

void* module_symbol(const std::string& name, const char* symbol) {
  static std::mutex mutex;
  static std::map<std::string, void*> opened;  // never closed: their code may run until exit
  const std::lock_guard<std::mutex> lock(mutex);
  void*& handle = opened[name];
  if (handle == nullptr) {
    const std::string file = module_folder() + "/" + name + ".so";
    // RTLD_NOW: a module that does not match this program fails here, in words, not later at a
    // call it cannot resolve. RTLD_LOCAL: its symbols do not stand in for the program's.
    handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* error = dlerror();
      std::string why = error ? error : "unknown error";
      // dlerror() names the file first ("FILE: cannot open shared object file: ..."): once is enough.
      if (why.starts_with(file + ": ")) why.erase(0, file.size() + 2);
      std::error_code ignored;
      const bool present = std::filesystem::exists(file, ignored);
      throw IoError(
          "cannot open isotope's module " + file + ": " + why +
          (present ? " (the module or a library it needs is damaged or missing: 'ldd " + file + "' lists what it needs)"
                   : " (it is installed with the isotope command; build or install isotope again)"));
    }
  }
  dlerror();
  void* address = dlsym(handle, symbol);
  if (address == nullptr)
    throw IoError("isotope's module " + name + ".so has no " + symbol +
                  ": it belongs to another isotope (build or install isotope again)");
  return address;
}

}  // namespace isotope::tools

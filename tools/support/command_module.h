#pragma once
// The command's modules: the parts of one command that need a large library no other command
// needs. `isotope serve` needs cpp-httplib, which loads and initializes OpenSSL; plots need PLplot;
// a process an MPI launcher started needs Open MPI. Those parts are built as shared modules and
// opened only when they are first used, so the other commands start without loading those
// libraries. A program linked with all of them spends 10 ms starting, against 1.3 ms without them
// (docs/DESIGN.md, "Start-up").
//
// The modules live in one folder, found from the running program's path: ISOTOPE_MODULE_DIR,
// relative to the folder the program is in. That is LIBDIR/isotope (lib/isotope, or
// lib/x86_64-linux-gnu/isotope under /usr) once installed, and the same relative place in the
// build tree.
//
// A module and the command are built together, by one compiler, against one libstdc++: what one
// throws, the other catches by type (libstdc++ matches the types of a module's copy of a class by
// name).
#include <string>

namespace isotope::tools {

// The address of `symbol` in module `name` (NAME.so in the modules' folder), opened on first use
// and kept open. Throws IoError naming the module's file and what went wrong, for example a file
// that is missing or was built for another isotope.
void* module_symbol(const std::string& name, const char* symbol);

template <class Function>
Function* module_function(const std::string& name, const char* symbol) {
  return reinterpret_cast<Function*>(module_symbol(name, symbol));
}

// The folder module_symbol() looks in.
std::string module_folder();

}  // namespace isotope::tools

#pragma once
// The temporary files a process has open (an AtomicFile's, a distributed convert's hand-over, a
// volume's hierarchy store and its folder), so that a process told to end at once can remove them
// first: under mpirun, a rank that fails or is killed makes mpirun end every other rank with
// SIGTERM, then SIGKILL, and a rank blocked in a collective cannot unwind to its destructors; the
// isotope command's Ctrl-C ends it at once outside a convert (the command's signal handler). Removal is
// async-signal-safe.
#include <string>

namespace isotope {

// Returns a slot for unregister_temporary, or -1 when all slots are taken (the file is then only
// removed by its owner's destructor, as always).
int register_temporary(const std::string& path) noexcept;
// The same for a folder of this process's own (mkdtemp, mode 0700) that holds files only: removed
// with the files in it, which need not be registered.
int register_temporary_folder(const std::string& path) noexcept;
void unregister_temporary(int slot) noexcept;
// Unlinks every registered file, then removes every registered folder with the files still in it
// (one level, and only where the folder is still this user's with mode 0700). Async-signal-safe:
// for a signal handler.
void remove_temporaries_now() noexcept;

}  // namespace isotope

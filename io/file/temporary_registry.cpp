#include "io/file/temporary_registry.h"

#include <dirent.h>
#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>

namespace isotope {
namespace {

constexpr int kSlots = 32;
constexpr size_t kPathBytes = 4096;
enum State : int { kFree = 0, kWriting = 1, kReady = 2 };
struct Slot {
  std::atomic<int> state{kFree};
  char path[kPathBytes];
};
Slot g_slots[kSlots];

}  // namespace

int register_temporary(const std::string& path) noexcept {
  if (path.size() >= kPathBytes) return -1;
  for (int i = 0; i < kSlots; ++i) {
    int expected = kFree;
    if (!g_slots[i].state.compare_exchange_strong(expected, kWriting)) continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].state.store(kReady);
    return i;
  }
  return -1;
}

void unregister_temporary(int slot) noexcept {
  if (slot >= 0 && slot < kSlots) g_slots[slot].state.store(kFree);
}

namespace {

bool dot_or_dot_dot(const char* name) {
  return name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'));
}

// Unlinks the files in FOLDER, one level down: a registered folder is the process's own (a
// volume's hierarchy store, mode 0700), and holds files only, its store's temporary and the
// scratch files beside it, some of which the signal may have met made but not yet registered, or
// not yet unlinked as scratch files are at once. System calls only (getdents64, unlinkat):
// async-signal-safe.
void empty_folder(const char* folder) noexcept {
  const int fd = ::open(folder, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  alignas(dirent64) char entries[4096];
  for (ssize_t n; (n = ::getdents64(fd, entries, sizeof entries)) > 0;)
    for (ssize_t at = 0; at < n;) {
      const auto* entry = reinterpret_cast<const dirent64*>(entries + at);
      if (!dot_or_dot_dot(entry->d_name)) ::unlinkat(fd, entry->d_name, 0);
      at += entry->d_reclen;
    }
  ::close(fd);
}

}  // namespace

void remove_temporaries_now() noexcept {
  for (Slot& s : g_slots)
    if (s.state.load() == kReady) ::unlink(s.path);
  // Then the folders (unlink refuses a folder), emptied first of what the files above left there.
  for (Slot& s : g_slots) {
    // Again while the other threads, still running, make files there (a few times at most).
    for (int tries = 0; s.state.load() == kReady && ::rmdir(s.path) != 0 && errno == ENOTEMPTY && tries < 4; ++tries)
      empty_folder(s.path);
  }
}

}  // namespace isotope

#include "io/file/temporary_registry.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
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
  // Counts the slot's unregistrations: a signal handler that read a path while the slot was freed
  // and taken again (the handler runs while the other threads go on) sees it changed and skips it.
  std::atomic<unsigned> generation{0};
  bool folder = false;
  char path[kPathBytes] = {};
};
// Constant-initialized (all zero, in .bss): no constructor runs at start-up, and a slot's pages are
// touched only when a path is first registered in it. A constructor writing each slot's state would
// fault in 32 pages, one a slot, in every process (docs/METHOD.md, "Fresh memory").
constinit Slot g_slots[kSlots];

int take_slot(const std::string& path, bool folder) noexcept {
  if (path.size() >= kPathBytes) return -1;
  for (int i = 0; i < kSlots; ++i) {
    int expected = kFree;
    if (!g_slots[i].state.compare_exchange_strong(expected, kWriting)) continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].folder = folder;
    g_slots[i].state.store(kReady);
    return i;
  }
  return -1;
}

// The slot's path and kind as registered, copied into OUT; false when the slot is not registered or
// changed while it was read.
bool read_slot(const Slot& s, char (&out)[kPathBytes], bool& folder) noexcept {
  const unsigned generation = s.generation.load();
  if (s.state.load() != kReady) return false;
  folder = s.folder;
  for (size_t i = 0; i < kPathBytes; ++i)
    if ((out[i] = s.path[i]) == '\0') break;
  out[kPathBytes - 1] = '\0';
  return s.state.load() == kReady && s.generation.load() == generation;
}

bool dot_or_dot_dot(const char* name) {
  return name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'));
}

// Unlinks the files in FOLDER, one level down, when it is this process's own private folder (a
// folder, not a link to one, owned by this user, of mode 0700): it holds files only, a store's
// temporary and the scratch files beside it, some of which the signal may have met made but not
// yet registered, or not yet unlinked as scratch files are at once. System calls only (getdents64,
// unlinkat): async-signal-safe.
void empty_folder(const char* folder) noexcept {
  const int fd = ::open(folder, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return;
  struct stat st {};
  if (::fstat(fd, &st) == 0 && st.st_uid == ::geteuid() && (st.st_mode & 07777) == 0700) {
    alignas(dirent64) char entries[4096];
    for (ssize_t n; (n = ::getdents64(fd, entries, sizeof entries)) > 0;)
      for (ssize_t at = 0; at < n;) {
        const auto* entry = reinterpret_cast<const dirent64*>(entries + at);
        if (!dot_or_dot_dot(entry->d_name)) ::unlinkat(fd, entry->d_name, 0);
        at += entry->d_reclen;
      }
  }
  ::close(fd);
}

}  // namespace

int register_temporary(const std::string& path) noexcept { return take_slot(path, false); }

int register_temporary_folder(const std::string& path) noexcept { return take_slot(path, true); }

void unregister_temporary(int slot) noexcept {
  if (slot < 0 || slot >= kSlots) return;
  g_slots[slot].generation.fetch_add(1);
  g_slots[slot].state.store(kFree);
}

void remove_temporaries_now() noexcept {
  char path[kPathBytes];
  bool folder = false;
  for (const Slot& s : g_slots)
    if (read_slot(s, path, folder) && !folder) ::unlink(path);
  // Then the folders, emptied first of what the files above left there; again while the other
  // threads, still running, make files there (a few times at most).
  for (const Slot& s : g_slots) {
    if (!read_slot(s, path, folder) || !folder) continue;
    for (int tries = 0; ::rmdir(path) != 0 && (errno == ENOTEMPTY || errno == EEXIST) && tries < 4; ++tries)
      empty_folder(path);
  }
}

}  // namespace isotope

#include "io/file/temporary_registry.h"

#include <unistd.h>

#include <atomic>
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

void remove_temporaries_now() noexcept {
  for (Slot& s : g_slots)
    if (s.state.load() == kReady) ::unlink(s.path);
  // Then the folders, emptied of the files above (unlink refuses a folder).
  for (Slot& s : g_slots)
    if (s.state.load() == kReady) ::rmdir(s.path);
}

}  // namespace isotope

#pragma once
// "A newer request from the same page supersedes an older one still running": each request of a
// client holds a Ticket whose flag (a RunContext::cancel) is raised as soon as a request of
// the same client with a larger sequence number arrives, or at once if one already has. Requests
// arrive on the server's threads in any order, so the numbers, not arrival, decide.
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace isotope::tools {

class Supersession {
 public:
  class Ticket {
   public:
    Ticket() = default;
    Ticket(Ticket&& o) noexcept
        : owner_(std::exchange(o.owner_, nullptr)), client_(std::move(o.client_)), flag_(std::move(o.flag_)) {}
    Ticket& operator=(Ticket&&) = delete;
    ~Ticket();
    const std::atomic<bool>* cancel() const { return flag_.get(); }
    bool superseded() const { return flag_ && flag_->load(); }

   private:
    friend class Supersession;
    Supersession* owner_ = nullptr;
    std::string client_;
    std::shared_ptr<std::atomic<bool>> flag_;
  };

  // The ticket of request `seq` of `client`.
  Ticket enter(const std::string& client, int64_t seq);
  size_t clients() const;

 private:
  struct Client {
    int64_t newest = -1;
    std::vector<std::pair<int64_t, std::shared_ptr<std::atomic<bool>>>> running;
  };
  void leave(const std::string& client, const std::atomic<bool>* flag);

  // Idle clients (pages closed long ago) are forgotten beyond this many, so the map stays small.
  static constexpr size_t kMaxClients = 4096;
  mutable std::mutex mutex_;
  std::unordered_map<std::string, Client> clients_;
};

}  // namespace isotope::tools

#include "tools/serve/supersession.h"

#include <algorithm>

namespace isotope::tools {

Supersession::Ticket::~Ticket() {
  if (owner_) owner_->leave(client_, flag_.get());
}

Supersession::Ticket Supersession::enter(const std::string& client, int64_t seq) {
  Ticket t;
  t.owner_ = this;
  t.client_ = client;
  t.flag_ = std::make_shared<std::atomic<bool>>(false);
  const std::lock_guard<std::mutex> lock(mutex_);
  if (clients_.size() >= kMaxClients && !clients_.count(client))
    std::erase_if(clients_, [](const auto& entry) { return entry.second.running.empty(); });
  Client& c = clients_[client];
  if (seq < c.newest) {
    t.flag_->store(true);
  } else {
    c.newest = seq;
    for (auto& [s, flag] : c.running)
      if (s < seq) flag->store(true);
  }
  c.running.emplace_back(seq, t.flag_);
  return t;
}

void Supersession::leave(const std::string& client, const std::atomic<bool>* flag) {
  const std::lock_guard<std::mutex> lock(mutex_);
  const auto it = clients_.find(client);
  if (it == clients_.end()) return;
  std::erase_if(it->second.running, [&](const auto& r) { return r.second.get() == flag; });
}

size_t Supersession::clients() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return clients_.size();
}

}  // namespace isotope::tools

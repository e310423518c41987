// Work shared among a group of processes (isotope/distribution.h): a failure settled together, and
// shares of items by cost.
#include <algorithm>
#include <exception>
#include <string>

#include "engine/core/byte_codec.h"
#include "isotope/distribution.h"
#include "isotope/extract.h"  // OptionError

namespace isotope {

void settle_together(const Distribution& group, const std::function<void()>& work) {
  // [failed][usage][passed on][rank][message]: a DistributedError caught here came from a nested
  // settle_together, which every process went through alike; it is passed on as it is.
  uint8_t failed = 0, usage = 0, passed_on = 0;
  int32_t origin = group.rank();
  std::string message;
  try {
    work();
  } catch (const DistributedError& e) {
    failed = 1, usage = e.usage_error, passed_on = 1, origin = e.rank, message = e.what();
  } catch (const OptionError& e) {
    failed = 1, usage = 1, message = "--" + e.option + ": " + e.message;
  } catch (const std::bad_alloc&) {
    failed = 1, message = "out of memory";
  } catch (const std::exception& e) {
    failed = 1, message = e.what();
  }
  ByteWriter mine;
  mine.put(failed);
  mine.put(usage);
  mine.put(passed_on);
  mine.put(origin);
  mine.put_array(message);
  const std::vector<std::vector<uint8_t>> all = group.all_gather(mine.bytes());
  int failures = 0;
  for (const std::vector<uint8_t>& bytes : all) failures += bytes.at(0);
  for (const std::vector<uint8_t>& bytes : all) {
    ByteReader r(bytes);
    if (r.get<uint8_t>() == 0) continue;
    const bool was_usage = r.get<uint8_t>() != 0;
    const bool was_passed_on = r.get<uint8_t>() != 0;
    const auto rank = r.get<int32_t>();
    std::string text;
    r.get_array(text);
    // What every process met (an input that does not exist) is said as one process says it; what
    // one met alone names it.
    if (!was_passed_on && failures < group.ranks())
      text = "rank " + std::to_string(rank) + " of " + std::to_string(group.ranks()) + ": " + text;
    throw DistributedError(rank, was_usage, text);
  }
}

std::vector<size_t> share_by_cost(const std::vector<double>& costs, int ranks) {
  std::vector<double> prefix(costs.size() + 1, 0.0);
  for (size_t i = 0; i < costs.size(); ++i) prefix[i + 1] = prefix[i] + std::max(0.0, costs[i]);
  const double total = prefix.back();
  std::vector<size_t> bounds(static_cast<size_t>(ranks) + 1, costs.size());
  bounds[0] = 0;
  for (int r = 1; r < ranks; ++r) {
    const double target = total * r / ranks;
    // The first bound whose prefix reaches the target, or the one before it when that is closer.
    auto i = static_cast<size_t>(std::lower_bound(prefix.begin(), prefix.end(), target) - prefix.begin());
    if (i > 0 && target - prefix[i - 1] < prefix[std::min(i, costs.size())] - target) --i;
    bounds[static_cast<size_t>(r)] =
        std::clamp(std::min(i, costs.size()), bounds[static_cast<size_t>(r) - 1], costs.size());
  }
  return bounds;
}

}  // namespace isotope

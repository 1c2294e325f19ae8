#pragma once
// A thread's last few values of one kind, reused while the same inputs come back (a rollout meets
// the same body frame and the same garment structure many times a frame).
#include <algorithm>
#include <cstddef>
#include <memory>
#include <vector>

namespace layersnet::dataset {

// The value in `recent` (most recent first) for which same(value) holds, moved to the front; else
// make()'s, put in front and the oldest dropped beyond `capacity`. `recent` is the caller's
// thread_local list.
template <class V, class Same, class Make>
std::shared_ptr<const V> kept_or_made(std::vector<std::shared_ptr<const V>>& recent, std::size_t capacity, Same&& same,
                                      Make&& make) {
  const auto found = std::find_if(recent.begin(), recent.end(), [&](const auto& kept) { return same(*kept); });
  if (found != recent.end()) {
    std::rotate(recent.begin(), found, found + 1);
  } else {
    recent.insert(recent.begin(), make());
    if (recent.size() > capacity) recent.pop_back();
  }
  return recent.front();
}

}  // namespace layersnet::dataset

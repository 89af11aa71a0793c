#pragma once
/// All hits of a batch of rays in compressed-row form: the hits of ray i are
/// uids[offsets[i] .. offsets[i + 1]). Reused from frame to frame, so the timed batch does not
/// allocate once the vectors have grown.

#include <cstdint>
#include <span>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

struct HitLists {
    std::vector<Uid> uids;
    std::vector<std::uint32_t> offsets{0};

    void clear() {
        uids.clear();
        offsets.assign(1, 0);
    }
    /// Closes the current ray's list.
    void end_ray() { offsets.push_back(static_cast<std::uint32_t>(uids.size())); }
    std::size_t rays() const { return offsets.size() - 1; }
    std::span<const Uid> of(std::size_t ray) const {
        return {uids.data() + offsets[ray], uids.data() + offsets[ray + 1]};
    }
};

}  // namespace rcb

#pragma once
/// The exact scan of a dense box array: every box tested with the segment's slabs, hits visited in
/// array order. Brute force in scalar form, for structures whose own traversal cannot take a
/// segment (the peers' fallbacks for zero-length or far segments).

#include <span>

#include "core/base/geometry.h"
#include "core/scene/scene.h"

namespace rcb {

/// Returns false when `visit` asked to stop. At the candidate level every box is yielded.
template <class Count, class Visit>
bool scan_boxes(const SegmentSlabs& slabs, std::span<const Aabb> boxes, std::span<const Uid> uids, Count& count,
                Visit&& visit) {
    count.box_tests(boxes.size());
    for (std::size_t i = 0; i < boxes.size(); ++i) {
        float tn = 0, tf;
        if (!Count::candidates && !slabs.clip(boxes[i], tn, tf)) continue;
        count.hits();
        if (!visit(uids[i], tn)) return false;
    }
    return true;
}

}  // namespace rcb

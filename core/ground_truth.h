#pragma once
/// Ground truth: brute force in double precision, with the tolerance of docs/architecture.md.
///
/// For a box B and a segment S let m be the largest absolute coordinate of B and S, and
/// ε = kRelativeTolerance · m. Rounding may move any coordinate, the box's and the segment's end
/// points alike, by up to ε. So
///   - S must hit B when S shortened by ε at both ends meets B shrunk by ε on every side (an axis
///     thinner than 2ε shrinks to its mid-plane, so flat and zero-volume boxes crossed squarely
///     still must be reported);
///   - S must miss B when S lengthened by ε at both ends does not meet B grown by ε on every side;
///   - otherwise S touches B within rounding, and a structure may report it or not.
/// (Distances are per axis, L∞: "by ε" moves each coordinate by at most ε.)
/// ε is about a hundred times float's rounding of the coordinates, so a correct float structure
/// never disagrees with a "must", while any real traversal bug shows up as a mismatch.

#include <cstdint>
#include <span>
#include <vector>

#include "core/hit_lists.h"
#include "core/scene.h"

namespace rcb {

inline constexpr double kRelativeTolerance = 1e-5;

enum class Contact { miss, touch, hit };

Contact classify_contact(const Segmentd& segment, const Aabbd& box);

/// One disagreement between a structure and the ground truth.
struct Discrepancy {
    std::uint32_t ray = 0;
    Uid uid = 0;
    enum Kind { missed, extra, duplicate } kind = missed;
};

struct Verification {
    std::uint64_t missed = 0;           ///< must-hit objects the structure did not report
    std::uint64_t extra = 0;            ///< reported objects that the segment clearly misses (or not live)
    std::uint64_t duplicate = 0;        ///< objects reported more than once for one ray
    std::vector<Discrepancy> examples;  ///< the first few, for messages

    std::uint64_t mismatches() const { return missed + extra + duplicate; }
};

class GroundTruth {
public:
    /// Snapshot of the live objects (in double).
    explicit GroundTruth(const std::vector<Object>& objects);

    /// Objects the segment must hit and those it touches within rounding, each sorted by uid.
    void classify(const Segment& segment, std::vector<Uid>& must, std::vector<Uid>& touch) const;

    /// Compares every ray's reported hits; parallel over rays. Keeps up to `max_examples` examples.
    Verification verify(std::span<const Segment> rays, const HitLists& hits, std::size_t max_examples = 10) const;

private:
    std::vector<double> min_[3], max_[3];
    std::vector<double> magnitude_;  // largest absolute coordinate of each box
    std::vector<Uid> uids_;
};

}  // namespace rcb

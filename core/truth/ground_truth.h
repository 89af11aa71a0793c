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
///
/// Shapes (shape.h) follow the same rule: every point of the segment and of the shape may move by
/// up to ε per axis. A segment must hit a shape when it does under every such move, must miss it
/// when it does under none; classify_shape_contact decides it with error bounds instead of
/// enumerating moves (the sign of each orientation determinant of a triangle test, the distance of
/// a sphere or capsule, the box test in an obb's own frame with ε grown by √3 for the rotation).

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/truth/hit_lists.h"
#include "core/scene/scene.h"

namespace rcb {

inline constexpr double kRelativeTolerance = 1e-5;

enum class Contact { miss, touch, hit };

Contact classify_contact(const Segmentd& segment, const Aabbd& box);
/// The contact of a segment with a shape (a box-kind shape: use classify_contact), with the ε of
/// the segment and of the shape's bounds.
Contact classify_shape_contact(const Segmentd& segment, const Shape& shape);

/// Which truth: hits of the objects' boxes, or of their exact shapes (the same for box objects).
enum class Truth { boxes, shapes };

/// What a configuration promises: every object that must be hit at level `lower` is reported, and
/// nothing that clearly misses at level `upper` (no upper level: any live object may be reported,
/// as by a broad phase's candidates; no lower level: hits may be lost, as by a peer without its
/// padding). The box query: {boxes, boxes}; the narrow phase: {shapes, shapes}; a tighter leaf
/// volume than the box: {shapes, boxes}; candidates: {boxes, none}; not robust: {none, boxes}.
struct Contract {
    std::optional<Truth> lower = Truth::boxes;
    std::optional<Truth> upper = Truth::boxes;
};

/// A closest hit: the object and the segment parameter where the segment enters its box.
struct TrueHit {
    Uid uid = 0;
    double t = 0;
};

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

    /// Accuracy against the shapes' truth, whatever the contract: touches count as neither right
    /// nor wrong (a touched object reported is correct, one left out is not missed).
    std::uint64_t returned = 0;  ///< distinct objects reported
    std::uint64_t correct = 0;   ///< of those, the ones whose shape is hit or touched
    std::uint64_t relevant = 0;  ///< shapes that must be hit, plus touched ones reported

    std::uint64_t mismatches() const { return missed + extra + duplicate; }
};

class GroundTruth {
public:
    /// Snapshot of the live objects (in double).
    explicit GroundTruth(const std::vector<Object>& objects);

    /// Objects the segment must hit and those it touches within rounding, each sorted by uid.
    void classify(const Segment& segment, std::vector<Uid>& must, std::vector<Uid>& touch,
                  Truth level = Truth::boxes) const;

    /// Compares every ray's reported hits with `contract`; parallel over rays. Keeps up to
    /// `max_examples` examples.
    Verification verify(std::span<const Segment> rays, const HitLists& hits, const Contract& contract = {},
                        std::size_t max_examples = 10) const;
    /// The same for rays of several query kinds (`kinds[i]` for ray i; empty: all hits for every
    /// ray). A closest or any ray's answer is at most one uid: none only when nothing must be hit,
    /// never one clearly missed, and for closest none clearly entered after an object that must
    /// be hit (docs/accuracy.md, "Query kinds"); a second uid counts as extra.
    Verification verify(std::span<const Segment> rays, std::span<const QueryKind> kinds, const HitLists& hits,
                        const Contract& contract = {}, std::size_t max_examples = 10) const;

    /// The closest-hit truth in double: the object whose box the segment enters first (the
    /// smallest entry parameter t in [0, 1], 0 when it starts inside), ties to the smallest uid.
    std::optional<TrueHit> closest(const Segment& segment) const;
    /// The any-hit truth in double: whether the segment meets any box.
    bool any(const Segment& segment) const;

    bool has_shapes() const { return !shaped_.empty(); }

private:
    /// An object whose box the segment does not clearly miss, with its box and shape contacts.
    struct Contacts {
        Uid uid;
        Contact box, shape;
        bool shaped;             ///< the object has a shape (a box's entry bounds the shape's from below)
        double t_early, t_late;  ///< the box's entry under rounding (ground_truth.cpp, BoxContact)
    };
    /// Every such object of the segment, sorted by uid.
    void contacts(const Segment& segment, std::vector<Contacts>& out) const;

    std::vector<double> min_[3], max_[3];
    std::vector<double> magnitude_;  // largest absolute coordinate of each box
    std::vector<Uid> uids_;
    std::vector<std::uint32_t> shape_of_;  // index into shaped_, or kNoShape for a box
    std::vector<Shape> shaped_;
};

}  // namespace rcb

#pragma once
/// Peer: Bullet's dynamic AABB tree btDbvt (Debian libbullet-dev, single precision), used the way
/// btDbvtBroadphase uses it: a leaf per object inserted, updated (btDbvt::update: remove and
/// reinsert) and removed as the frame's changes arrive, `optimize_passes` passes of
/// btDbvt::optimizeIncremental at each commit, and rays through btDbvt::rayTestInternal (the
/// persistent-stack ray test btDbvtBroadphase uses for world ray casts) with a collector.
///
/// Exactness: btDbvt's ray test (btRayAabb2) is a float test with strict comparisons
/// (tmin < λmax and tmax > λmin), so a segment that only touches a box, or runs along a face, can be
/// missed, and nearly-touching boxes can be reported. Both are reconciled: the leaf volumes given
/// to Bullet are the boxes padded outward by `pad` = 1e-4 · S (S: a scale at least the largest
/// |coordinate| of any box, grown ×2 and all leaves re-padded when a box exceeds it), so every box
/// the segment touches is strictly crossed in Bullet's float arithmetic, and each candidate leaf
/// Bullet delivers is decided by rcb's SegmentSlabs test on the unpadded box (counted as N_RB). The
/// hits, their t and the touching rule are exactly those of every rcb structure. Segments with a
/// coordinate beyond kFarFactor · S or non-finite take an exact fallback, a scan of the dense box
/// array (where the padding would no longer provably exceed the rounding). Zero-length segments go
/// through Bullet: its ray test turns a zero direction into BT_LARGE_FLOAT, which with the padding is
/// an exact point-in-padded-box test, and the exact test decides.
///
/// Counters: N_RB = candidate leaves (plus fallback tests), N_TP = hits; btDbvt's node visits are
/// inside its inline loop and not observable, so N_T stays 0 for this peer.

#include <cstdint>
#include <memory>
#include <tuple>
#include <vector>

#include "core/params.h"
#include "core/box_scan.h"
#include "core/slot_boxes.h"
#include "core/structure.h"

class btDbvt;
struct btDbvtNode;

namespace rcb {

class BulletDbvt : public StructureBase<BulletDbvt> {
public:
    struct Params {
        int optimize_passes = 1;
        static constexpr auto fields() {
            return std::tuple{Field{"optimize_passes", &Params::optimize_passes, 0, 1024,
                                    "btDbvt::optimizeIncremental passes per commit (btDbvtBroadphase's default is 1)"}};
        }
    };

    static constexpr float kFarFactor = 16.0f;
    static constexpr float kPadRelative = 1e-4f;
    /// Below this scale (every box within 1e-8 of the origin) btDbvt's fixed constants outweigh the
    /// padding and it misses hits; the exact scan answers instead, as for Embree.
    static constexpr float kMinScale = 1e-8f;

    BulletDbvt();
    explicit BulletDbvt(const Params& params);
    ~BulletDbvt() override;
    BulletDbvt(const BulletDbvt&) = delete;
    BulletDbvt& operator=(const BulletDbvt&) = delete;

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override;
    std::size_t size() const override { return objects_.size(); }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void validate() const override;

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit);

    /// The collector's view of one query (public for the policy in the .cpp).
    struct Query {
        const SegmentSlabs* slabs;
        const BulletDbvt* self;
        void* visit;
        bool (*on_hit)(void* visit, Uid uid, float t);
        std::uint64_t tests = 0;
        std::uint64_t hits = 0;
        bool stopped = false;
    };
    const Aabb& box_at(std::uint32_t slot) const { return objects_.box(slot); }
    Uid uid_at(std::uint32_t slot) const { return objects_.uid(slot); }

private:
    /// Runs btDbvt's ray test; false when the segment needs the exact fallback.
    bool dbvt_query(const Segment& s, Query& q);
    void set_leaf(std::uint32_t slot);  // inserts or updates the slot's leaf with its padded box
    /// Grows the scale (and re-pads every leaf) when `box` lies beyond it.
    void cover(const Aabb& box);

    Params params_;
    std::unique_ptr<btDbvt> tree_;
    struct Stack;
    std::unique_ptr<Stack> stack_;  // rayTestInternal's persistent stack
    SlotBoxes objects_;
    std::vector<btDbvtNode*> leaves_;  // slot-indexed, as objects_
    float scale_ = 0;                  // S in the comment above; 0 before the first box
    std::uint64_t repads_ = 0;
};

template <class Count, class Visit>
void BulletDbvt::traverse(const Segment& s, Count& count, Visit&& visit) {
    const SegmentSlabs slabs(s);
    Query q{&slabs, this, &visit,
            [](void* v, Uid uid, float t) { return bool((*static_cast<std::remove_reference_t<Visit>*>(v))(uid, t)); }};
    if (!dbvt_query(s, q)) {
        scan_boxes(slabs, std::span<const Aabb>(objects_.boxes()), std::span<const Uid>(objects_.uids()), count,
                   visit);  // the exact fallback
        return;
    }
    count.box_tests(q.tests);
    count.hits(q.hits);
}

}  // namespace rcb

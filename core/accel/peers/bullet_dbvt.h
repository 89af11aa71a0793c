#pragma once
/// Peer: Bullet's dynamic AABB tree btDbvt used as btDbvtBroadphase uses it: a leaf per object,
/// updates as remove and reinsert, `optimize_passes` of optimizeIncremental per commit, rays through
/// rayTestInternal. btDbvt's float ray test can miss touching boxes, so its leaves are padded boxes
/// and each candidate is decided by rcb's own slab test on the unpadded box (exact_collector.h):
/// hits equal every rcb structure's. Far or non-finite segments go to an exact scan. Closest and
/// any hit: rayTestInternal takes its ray length lambda_max by value and has no exit, so its walk
/// cannot be shortened at a hit nor stopped; an any-hit query tests no leaf after its first hit.
/// Counters: N_RB = candidate leaves tested plus scan tests; N_T, N_TH and N_MP from the counting
/// pass's replica of rayTestInternal's walk (the library's loop has no hook). docs/structures.md
/// has the exactness argument.

#include <cstdint>
#include <memory>
#include <tuple>
#include <vector>

#include "core/accel/params.h"
#include "core/accel/common/exact_collector.h"
#include "core/accel/common/slot_boxes.h"
#include "core/accel/structure.h"

class btDbvt;
struct btDbvtNode;

namespace rcb {

class BulletDbvt : public StructureBase<BulletDbvt> {
public:
    struct Params {
        int optimize_passes = 1;
        bool robust = true;
        static constexpr auto fields() {
            return std::tuple{Field{"optimize_passes", &Params::optimize_passes, 0, 1024,
                                    "btDbvt::optimizeIncremental passes per commit (btDbvtBroadphase's default is 1)"},
                              Field{"robust", &Params::robust, 0, 1,
                                    "pad the leaves (false: btDbvt as shipped, unpadded: its float ray test may lose "
                                    "touching hits; the result then promises no hit)",
                                    kNotTuned}};
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

    float pad() const { return params_.robust ? kPadRelative * scale_ : 0.0f; }

private:
    /// Runs btDbvt's ray test, every leaf it reaches offered to `collect`, or with `count` (the
    /// counting pass) the same walk with its node visits counted; false when the segment needs the
    /// exact fallback.
    bool dbvt_query(const Segment& s, ExactCollector& collect, Counting* count = nullptr);
    void set_leaf(std::uint32_t slot);  // inserts or updates the slot's leaf with its padded box
    /// Grows the scale (and re-pads every leaf) when `box` lies beyond it.
    void cover(const Aabb& box);

    Params params_;
    std::unique_ptr<btDbvt> tree_;
    struct Stack;
    std::unique_ptr<Stack> stack_;  // rayTestInternal's persistent stack
    std::vector<const btDbvtNode*> counting_stack_;
    SlotBoxes objects_;
    std::vector<btDbvtNode*> leaves_;  // slot-indexed, as objects_
    float scale_ = 0;                  // S in the comment above; 0 before the first box
    std::uint64_t repads_ = 0;
};

template <class Count, class Visit>
void BulletDbvt::traverse(const Segment& s, Count& count, Visit&& visit) {
    traverse_or_scan(s, objects_, count, visit, [&](ExactCollector& collect) {
        Counting* counting = nullptr;
        if constexpr (Count::enabled) counting = &count;
        return dbvt_query(s, collect, counting);
    });
}

}  // namespace rcb

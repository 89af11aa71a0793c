#pragma once
/// Peer: Bullet's dynamic AABB tree btDbvt, run the way btDbvtBroadphase (Bullet 3,
/// btDbvtBroadphase.cpp) runs its trees, or raw (`variant`). A leaf per object; rays through
/// btDbvt::rayTestInternal. btDbvt's float ray test can miss touching boxes, so its leaves are
/// padded boxes and each candidate is decided by rcb's own slab test on the unpadded box
/// (exact_collector.h): hits equal every rcb structure's, whatever the leaves' fat volumes. Far or
/// non-finite segments go to an exact scan.
///
/// `broadphase` (the default), as btDbvtBroadphase:
///   - two trees, a dynamic set and a fixed set (m_sets[0], m_sets[1]); a new object enters the
///     dynamic set with its tight box (createProxy);
///   - a move (setAabb): an object in the fixed set goes back to the dynamic set with its tight
///     box; in the dynamic set, a box that overlaps its leaf's volume is a "moving" update,
///     btDbvt::update(leaf, volume, velocity, margin): skipped when the leaf's volume still
///     contains the box, else re-inserted with the box grown by `margin` and, along the direction
///     of motion, by `prediction` × the box's half extents (m_prediction); a box that left its leaf
///     entirely "teleports": re-inserted tight;
///   - per commit (collide): optimizeIncremental(optimize_passes + dynamic leaves ×
///     dynamic_updates / 100) on the dynamic set, 1 + fixed leaves × fixed_updates / 100 passes on
///     the fixed set while fixed leaves remain to be optimised (m_fixedleft), then every object not
///     moved in the last frame (its stage, STAGECOUNT = 2) moves to the fixed set with its tight box;
///   - rays test both sets (rayTest).
/// `raw`: one btDbvt, every move a remove and reinsert of the tight box (btDbvt::update(leaf,
/// volume)), optimizeIncremental(optimize_passes + leaves × dynamic_updates / 100) per commit.
/// Closest and any hit: rayTestInternal takes its ray length lambda_max by value and has no exit,
/// so its walk cannot be shortened at a hit nor stopped; an any-hit query tests no leaf after its
/// first hit. Counters: N_RB = candidate leaves tested plus scan tests; N_T, N_TH and N_MP from
/// the counting pass's replica of rayTestInternal's walk (the library's loop has no hook).
/// `cast_threads` runs the timed batch, every query kind, on a task arena, each thread with its own
/// ray stack, as btDbvtBroadphase::rayTest does under BT_THREADSAFE (one stack per thread,
/// m_rayTestStacks): btDbvt::rayTestInternal is const on the tree and takes the caller's stack
/// ("uses a persistent stack", btDbvt.h), so threads share the trees read-only.
/// docs/structures.md has the exactness argument and the defaults' sources.

#include <cstdint>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "accel/interface/params.h"
#include "accel/common/exact_collector.h"
#include "accel/common/slot_boxes.h"
#include "accel/interface/structure.h"

class btDbvt;
struct btDbvtNode;
struct btDbvtAabbMm;

namespace rcb {

/// A thread's rayTestInternal stack (btDbvtBroadphase keeps one per thread, m_rayTestStacks).
struct BulletRayScratch {
    struct Stack;
    std::unique_ptr<Stack> stack;  // made by BulletDbvt::fit
    BulletRayScratch();
    ~BulletRayScratch();
    BulletRayScratch(BulletRayScratch&&) noexcept;
    BulletRayScratch& operator=(BulletRayScratch&&) noexcept;
    std::size_t memory_bytes() const;
};

class BulletDbvt : public StructureBase<BulletDbvt, BulletRayScratch> {
public:
    /// Params::variant, parsed once by the constructor; the enumerators follow kVariantChoices.
    enum class Variant : std::uint8_t { broadphase, raw };
    static constexpr const char* kVariantChoices = "broadphase,raw";

    struct Params {
        std::string variant = "broadphase";
        double margin = 0;
        double prediction = 0;
        int optimize_passes = 1;
        int dynamic_updates = 0;
        int fixed_updates = 1;
        bool robust = true;
        int cast_threads = 1;
        static constexpr auto fields() {
            return std::tuple{
                Field{"variant", &Params::variant, 0, 0,
                      "broadphase: two trees as btDbvtBroadphase keeps them (fat volumes, moves inside them skipped, "
                      "still objects in a fixed set); raw: one btDbvt, every move re-inserted",
                      choices(kVariantChoices)},
                Field{"margin", &Params::margin, 0, 1,
                      "broadphase: scene units (metres in physics scenes) a re-inserted leaf is grown by "
                      "(DBVT_BP_MARGIN, compiled out in "
                      "Bullet 3: 0; Bullet 2's 0.05 for metre-sized bodies)"},
                Field{"prediction", &Params::prediction, 0, 4,
                      "broadphase: a re-inserted leaf is grown along the motion by this many half extents "
                      "(btDbvtBroadphase::m_prediction, default 0)"},
                Field{"optimize_passes", &Params::optimize_passes, 0, 1024,
                      "btDbvt::optimizeIncremental passes per commit on the dynamic tree, beside dynamic_updates "
                      "(btDbvtBroadphase::collide runs 1)"},
                Field{"dynamic_updates", &Params::dynamic_updates, 0, 100,
                      "further optimizeIncremental passes per commit, in percent of the dynamic tree's leaves "
                      "(btDbvtBroadphase::m_dupdates, default 0)"},
                Field{"fixed_updates", &Params::fixed_updates, 0, 100,
                      "broadphase: optimizeIncremental passes on the fixed tree per commit after objects joined it, "
                      "1 + this percent of its leaves (btDbvtBroadphase::m_fupdates, default 1)"},
                Field{"robust", &Params::robust, 0, 1,
                      "pad the leaves (false: btDbvt as shipped, unpadded: its float ray test may lose "
                      "touching hits; the result then promises no hit)",
                      kNotTuned},
                cast_threads_field<Params>()};
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
    void check() const override;

    /// StructureBase's hooks: the trees are ready after every change; a scratch is a ray stack.
    void prepare() {}
    void fit(BulletRayScratch& scratch) const;
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, BulletRayScratch& scratch) const;

    float pad() const { return params_.robust ? kPadRelative * scale_ : 0.0f; }

private:
    /// Where a slot's leaf lives: a stage of the dynamic set (the commit count modulo kStages when
    /// it last changed) or the fixed set (btDbvtBroadphase's proxy->stage, STAGECOUNT = fixed).
    static constexpr std::uint8_t kStages = 2, kFixed = kStages;

    /// Runs btDbvt's ray test on both trees, every leaf it reaches offered to `collect`, or with
    /// `count` (the counting pass) the same walk with its node visits counted; false when the
    /// segment needs the exact fallback.
    bool dbvt_query(const Segment& s, ExactCollector& collect, Counting* count, BulletRayScratch& scratch) const;
    btDbvt& tree_of(std::uint32_t slot) { return *trees_[stage_[slot] == kFixed ? 1 : 0]; }
    /// The slot's padded box as a btDbvt volume.
    btDbvtAabbMm volume_of(std::uint32_t slot) const;
    /// A new leaf for the slot, its tight (padded) box in `tree`.
    void insert_leaf(std::uint32_t slot, btDbvt& tree);
    /// btDbvtBroadphase::setAabb for a slot whose box changed from `old`.
    void update_leaf(std::uint32_t slot, const Aabb& old);
    void set_stage(std::uint32_t slot, std::uint8_t stage);  ///< off its stage list, onto the new one
    /// Grows the scale (and re-pads every leaf) when `box` lies beyond it.
    void cover(const Aabb& box);
    /// btDbvtBroadphase::collide's stage advance: the objects of the oldest stage join the fixed set.
    void retire_stage();

    Params params_;
    Variant variant_;
    std::unique_ptr<btDbvt> trees_[2];                       // the dynamic set and the fixed set (unused when raw)
    mutable std::vector<const btDbvtNode*> counting_stack_;  // the counting pass's (one thread)
    SlotBoxes objects_;
    std::vector<btDbvtNode*> leaves_;             // slot-indexed, as objects_
    std::vector<std::uint8_t> stage_;             // slot-indexed: a dynamic stage or kFixed
    std::vector<std::uint32_t> position_;         // slot-indexed: the slot's index in its stage's list
    std::vector<std::uint32_t> staged_[kStages];  // the dynamic slots of each stage
    std::uint8_t stage_current_ = 0;
    int fixed_left_ = 0;  // btDbvtBroadphase::m_fixedleft
    float scale_ = 0;     // S in the comment above; 0 before the first box
    std::uint64_t repads_ = 0;
    std::uint64_t reinserts_ = 0;  // moves that changed the trees (btDbvtBroadphase's m_updates_done)
    std::uint64_t skipped_ = 0;    // moves that stayed inside their leaf's volume
    std::uint64_t retired_ = 0;    // leaves moved to the fixed set
};

template <class Count, class Visit>
void BulletDbvt::traverse(const Segment& s, Count& count, Visit&& visit, BulletRayScratch& scratch) const {
    traverse_or_scan(s, objects_, count, visit, [&](ExactCollector& collect) {
        Counting* counting = nullptr;
        if constexpr (Count::enabled) counting = &count;
        return dbvt_query(s, collect, counting, scratch);
    });
}

}  // namespace rcb

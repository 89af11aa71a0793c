#pragma once
/// Peer: Intel Embree 3 (Debian libembree-dev) over the objects' boxes, as a user geometry.
///
/// Embree keeps no boxes of its own for a user geometry: at commit it asks our bounds callback for
/// every primitive (primitive id = dense slot) and builds (or refits) its BVH; during a ray query
/// it calls our intersect callback for every primitive whose BVH leaf the ray reaches. All hits:
/// the callback records the hit (calls `visit`) and never commits it to the ray (tfar unchanged),
/// so Embree keeps traversing; when `visit` asks to stop, tfar is set to −∞ and every remaining
/// node is culled.
///
/// Exactness (how Embree's float ray–node culling is reconciled with rcb's closed-segment
/// semantics): Embree's user-geometry traversal is the non-robust one (its BVH4VirtualIntersector1
/// is instantiated with robust = false: node slabs computed as fma(bound, rdir, −org·rdir)), which
/// can cull a box the segment only touches. So (1) the bounds we hand Embree are padded outward by
/// `pad = 1e-4 · M` (M: the largest |coordinate| of the live boxes at this commit), far more than
/// the culling's rounding for rays whose coordinates stay within kFarFactor·M, and (2) the
/// intersect callback decides with rcb's own SegmentSlabs test on the unpadded box, so the hits,
/// their t and the touching rule are exactly those of every rcb structure. The Embree ray is
/// org = P0, dir = P1 − P0, tnear = 0, tfar = 1.
///
/// Rays Embree cannot take are answered by an exact fallback without Embree, a scan of the dense
/// box array with the same SegmentSlabs test (counted as box tests): zero-length segments
/// (dir = 0; Embree's rcp_safe would turn them into a tiny arbitrary direction), segments with a
/// non-finite coordinate, and segments reaching beyond kFarFactor·M, where the padding would no
/// longer be provably enough.
///
/// Embree's own range: it asserts (aborts) on a ray whose |origin| or |direction| exceeds its
/// FLT_LARGE (1.8e18) and silently leaves out of its BVH a primitive whose bounds do. Input files
/// stay within kMaxCoordinate (recording_io.h), far below; as a second line of defence for scenes
/// built in memory, the far limit is also capped at kEmbreeRange / 2 (so origin and direction
/// stay within kEmbreeRange), and when the padded boxes reach beyond kEmbreeRange Embree is given
/// no primitives and every segment takes the exact fallback. At the other end Embree works with
/// absolute constants (its rcp_safe turns direction components below 1e-18 into 1e-18), which the
/// padding no longer dominates in scenes a few 1e-12 across (hits were missed there): when every
/// box lies within kEmbreeMinScale of the origin, the exact fallback answers too.
///
/// Counters: N_RB = intersect-callback calls (leaf primitive tests) plus fallback tests, N_TP =
/// hits. Embree does not expose its node visits, so N_T stays 0 for this peer.
///
/// Build quality (Embree's documented semantics of rtcSetSceneBuildQuality /
/// rtcSetGeometryBuildQuality): `quality = low` makes a two-level scene whose geometry BVH is
/// built with the Morton builder; `medium` the default binned SAH; `refit = true` makes the geometry
/// RTC_BUILD_QUALITY_REFIT, so a commit after moves refits the existing BVH (Embree rebuilds when
/// the primitive count changes, i.e. after inserts or removes). The BVH is rebuilt or refitted at
/// every commit. `threads` bounds the commit's parallelism with a tbb::task_arena (Embree 3 with
/// TBB tasking runs its builders in the caller's arena); the device is not given a `threads=`
/// setting, which in Embree 3 would install a process-wide tbb::global_control.

#include <cstdint>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "core/params.h"
#include "core/box_scan.h"
#include "core/slot_boxes.h"
#include "core/structure.h"

namespace rcb {

class EmbreeBoxes : public StructureBase<EmbreeBoxes> {
public:
    struct Params {
        std::string quality = "medium";
        bool refit = false;
        int threads = 1;
        static constexpr auto fields() {
            return std::tuple{
                Field{"quality", &Params::quality, 0, 0,
                      "Embree build quality: low (Morton, two-level) or medium (binned SAH)", true, false,
                      "low,medium"},
                Field{"refit", &Params::refit, 0, 1,
                      "refit the BVH at commit (RTC_BUILD_QUALITY_REFIT) instead of rebuilding", true},
                Field{"threads", &Params::threads, 1, 64, "commit (build) threads, a TBB task arena", false}};
        }
    };

    /// Segments reaching beyond this × the largest box coordinate take the exact fallback.
    static constexpr float kFarFactor = 16.0f;
    static constexpr float kPadRelative = 1e-4f;
    /// Below Embree's FLT_LARGE (1.844e18) with margin.
    static constexpr float kEmbreeRange = 1e18f;
    /// Four orders of magnitude above the scale where Embree first missed a hit (1e-12).
    static constexpr float kEmbreeMinScale = 1e-8f;

    EmbreeBoxes();
    explicit EmbreeBoxes(const Params& params);
    ~EmbreeBoxes() override;
    EmbreeBoxes(const EmbreeBoxes&) = delete;
    EmbreeBoxes& operator=(const EmbreeBoxes&) = delete;

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

    /// What the intersect callback needs; public for the C callbacks in the .cpp.
    struct Query;
    struct Device;  // RTCDevice, RTCScene, RTCGeometry and the task arena
    const Aabb& box_at(std::uint32_t slot) const { return objects_.box(slot); }
    Uid uid_at(std::uint32_t slot) const { return objects_.uid(slot); }
    float pad() const { return pad_; }

private:
    /// Runs Embree on one segment; returns false when the segment needs the fallback.
    bool embree_query(const Segment& s, Query& q);

    Params params_;
    std::unique_ptr<Device> device_;
    SlotBoxes objects_;     // slot = Embree primitive id
    float pad_ = 0;         // padding of the bounds given to Embree at the last commit
    float far_ = 0;         // min(kFarFactor · M, kEmbreeRange / 2) at the last commit
    bool in_range_ = true;  // kEmbreeMinScale <= M and the padded boxes within kEmbreeRange: Embree holds them
    bool dirty_ = true;
    std::uint64_t commits_ = 0;
};

struct EmbreeBoxes::Query {
    const SegmentSlabs* slabs;
    const EmbreeBoxes* self;
    void* visit;
    bool (*on_hit)(void* visit, Uid uid, float t);
    std::uint64_t tests = 0;
    std::uint64_t hits = 0;
};

template <class Count, class Visit>
void EmbreeBoxes::traverse(const Segment& s, Count& count, Visit&& visit) {
    const SegmentSlabs slabs(s);
    Query q{&slabs, this, &visit,
            [](void* v, Uid uid, float t) { return bool((*static_cast<std::remove_reference_t<Visit>*>(v))(uid, t)); }};
    if (!embree_query(s, q)) {
        scan_boxes(slabs, std::span<const Aabb>(objects_.boxes()), std::span<const Uid>(objects_.uids()), count,
                   visit);  // the exact fallback
        return;
    }
    count.box_tests(q.tests);
    count.hits(q.hits);
}

}  // namespace rcb

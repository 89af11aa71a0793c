#pragma once
/// Peer: Intel Embree 3 over the objects' boxes as a user geometry (primitive id = dense slot).
/// Embree's user-geometry traversal is not robust, so the bounds it gets are padded and each
/// candidate primitive is decided by rcb's own slab test on the unpadded box (exact_collector.h):
/// hits, t and the touching rule equal every rcb structure's. All hits: rtcIntersect1, the
/// intersect callback recording each hit and never committing it, so Embree keeps traversing.
/// Closest hit: rtcIntersect1 with the callback clipping tfar to the nearest hit so far (entries
/// at exactly tfar still reach it: ties go to the smaller uid), so Embree culls what lies beyond.
/// Any hit: rtcOccluded1, Embree's occlusion query; the occluded callback marks the ray occluded
/// at the first exact hit, which ends the traversal. Rays Embree cannot take (zero length,
/// non-finite, beyond its range or the padding's) go to an exact scan. Builds: `quality` is the
/// scene's build quality when rebuilt every commit (low: Morton, medium: binned SAH). With `refit`
/// the scene is RTC_SCENE_FLAG_DYNAMIC at RTC_BUILD_QUALITY_LOW (Embree's two-level builder,
/// scene.cpp createUserGeometryAccel) and the geometry RTC_BUILD_QUALITY_REFIT: Embree builds its
/// BVH with binned SAH once and then only refits it while the primitive count stays
/// (bvh_refit.cpp BVHNRefitT::build: a user geometry's topology is its primitive count). On top,
/// the rebuild-versus-refit policy: a commit rebuilds when its frame inserted or removed objects
/// (`rebuild_on_inserts`) or every `rebuild_every` commits; the rebuild attaches a fresh geometry
/// under the other geometry ID, which Embree's two-level builder builds anew
/// (bvh_builder_twolevel.cpp setupLargeBuildRefBuilder: a new mesh), while the old one is
/// detached. Counters: N_RB = callback calls plus scan tests; N_T is not exposed
/// (0). `cast_threads` runs the timed batch, every query kind, on a task arena, every thread
/// calling rtcIntersect1 / rtcOccluded1 on the one committed scene with its own RTCIntersectContext
/// on its stack (Embree 3's per-call query context; Embree 4 passes it as RTCRayQueryContext in
/// RTCIntersectArguments). Embree allows it: "performing ray queries in a scene is thread-safe"
/// (Embree 3 API manual, doc/src/api.md, Embree API), once rtcCommitScene has returned and until
/// the next change (rtcCommitScene(3): modification, commit and tracing happen in sequence).
/// docs/structures.md has the exactness argument and the limits.

#include <cstdint>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "accel/interface/params.h"
#include "accel/common/exact_collector.h"
#include "accel/common/slot_boxes.h"
#include "accel/interface/structure.h"

namespace rcb {

/// An Embree query keeps its state (ray, query context, exact collector) on the calling thread's
/// stack (rtcIntersect1 and rtcOccluded1 are safe to call from many threads on a committed scene):
/// nothing per thread to hold.
struct EmbreeScratch {
    std::size_t memory_bytes() const { return 0; }
};

class EmbreeBoxes : public StructureBase<EmbreeBoxes, EmbreeScratch> {
public:
    /// Params::quality, parsed once by the constructor; the enumerators follow kQualityChoices.
    enum class Quality : std::uint8_t { low, medium };
    static constexpr const char* kQualityChoices = "low,medium";

    struct Params {
        std::string quality = "medium";
        bool refit = false;
        int threads = 1;
        bool robust = true;
        int rebuild_every = 0;
        bool rebuild_on_inserts = true;
        int cast_threads = 1;
        static constexpr auto fields() {
            return std::tuple{
                Field{"quality", &Params::quality, 0, 0,
                      "Embree build quality: low (Morton, two-level) or medium (binned SAH)", choices(kQualityChoices)},
                Field{"refit", &Params::refit, 0, 1,
                      "refit the BVH at commit (RTC_SCENE_FLAG_DYNAMIC, RTC_BUILD_QUALITY_REFIT) instead of "
                      "rebuilding"},
                Field{"rebuild_every", &Params::rebuild_every, 0, 1024,
                      "with refit: rebuild every this many commits that change the scene (0: only as the policy's "
                      "other rule and Embree's own, a changed object count, decide)"},
                Field{"rebuild_on_inserts", &Params::rebuild_on_inserts, 0, 1,
                      "with refit: rebuild at a commit whose frame inserted or removed objects (false: refit unless "
                      "the object count changed)"},
                Field{"threads", &Params::threads, 1, 64, "commit (build) threads, a TBB task arena", kNotTuned},
                Field{"robust", &Params::robust, 0, 1,
                      "pad the bounds Embree gets (false: Embree as shipped, unpadded: it may lose touching hits; "
                      "the result then promises no hit)",
                      kNotTuned},
                cast_threads_field<Params>()};
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
    void check() const override;

    /// StructureBase's hooks: the commit did the work; a scratch holds nothing.
    void prepare() {}
    void fit(EmbreeScratch&) const {}
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, EmbreeScratch&) const;

    struct Device;  // RTCDevice, RTCScene, RTCGeometry and the task arena
    /// For the bounds callback in the .cpp.
    const Aabb& box_at(std::uint32_t slot) const { return objects_.box(slot); }
    float pad() const { return pad_; }

private:
    /// Runs Embree on one segment, every primitive it reaches offered to `collect`: rtcOccluded1
    /// when `occluded` (any hit), else rtcIntersect1. False when the segment needs the fallback.
    bool embree_query(const Segment& s, ExactCollector& collect, bool occluded) const;

    Params params_;
    Quality quality_;
    std::unique_ptr<Device> device_;
    SlotBoxes objects_;     // slot = Embree primitive id
    float pad_ = 0;         // padding of the bounds given to Embree at the last commit
    float far_ = 0;         // min(kFarFactor · M, kEmbreeRange / 2) at the last commit
    bool in_range_ = true;  // kEmbreeMinScale <= M and the padded boxes within kEmbreeRange: Embree holds them
    /// Replaces the geometry by a fresh one under the other geometry ID (the policy's rebuild).
    void fresh_geometry();

    bool dirty_ = true;
    bool topology_changed_ = true;  // inserts or removes since the last commit
    std::uint64_t commits_ = 0;
    std::uint64_t rebuilds_ = 0;       // commits that rebuilt (every commit without refit)
    std::uint64_t since_rebuild_ = 0;  // commits since the last rebuild
    unsigned committed_count_ = 0;     // Embree's primitive count at the last commit
};

template <class Count, class Visit>
void EmbreeBoxes::traverse(const Segment& s, Count& count, Visit&& visit, EmbreeScratch&) const {
    traverse_or_scan(s, objects_, count, visit,
                     [&](ExactCollector& collect) { return embree_query(s, collect, StopsAtFirstHit<Visit>); });
}

}  // namespace rcb

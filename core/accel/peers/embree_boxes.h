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
/// non-finite, beyond its range or the padding's) go to an exact scan. `quality` and `refit` map to
/// Embree's build qualities. Counters: N_RB = callback calls plus scan tests; N_T is not exposed
/// (0). docs/structures.md has the exactness argument and the limits.

#include <cstdint>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "core/accel/params.h"
#include "core/accel/common/exact_collector.h"
#include "core/accel/common/slot_boxes.h"
#include "core/accel/structure.h"

namespace rcb {

class EmbreeBoxes : public StructureBase<EmbreeBoxes> {
public:
    /// Params::quality, parsed once by the constructor; the enumerators follow kQualityChoices.
    enum class Quality : std::uint8_t { low, medium };
    static constexpr const char* kQualityChoices = "low,medium";

    struct Params {
        std::string quality = "medium";
        bool refit = false;
        int threads = 1;
        bool robust = true;
        static constexpr auto fields() {
            return std::tuple{
                Field{"quality", &Params::quality, 0, 0,
                      "Embree build quality: low (Morton, two-level) or medium (binned SAH)", choices(kQualityChoices)},
                Field{"refit", &Params::refit, 0, 1,
                      "refit the BVH at commit (RTC_BUILD_QUALITY_REFIT) instead of rebuilding"},
                Field{"threads", &Params::threads, 1, 64, "commit (build) threads, a TBB task arena", kNotTuned},
                Field{"robust", &Params::robust, 0, 1,
                      "pad the bounds Embree gets (false: Embree as shipped, unpadded: it may lose touching hits; "
                      "the result then promises no hit)",
                      kNotTuned}};
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

    struct Device;  // RTCDevice, RTCScene, RTCGeometry and the task arena
    /// For the bounds callback in the .cpp.
    const Aabb& box_at(std::uint32_t slot) const { return objects_.box(slot); }
    float pad() const { return pad_; }

private:
    /// Runs Embree on one segment, every primitive it reaches offered to `collect`: rtcOccluded1
    /// when `occluded` (any hit), else rtcIntersect1. False when the segment needs the fallback.
    bool embree_query(const Segment& s, ExactCollector& collect, bool occluded);

    Params params_;
    Quality quality_;
    std::unique_ptr<Device> device_;
    SlotBoxes objects_;     // slot = Embree primitive id
    float pad_ = 0;         // padding of the bounds given to Embree at the last commit
    float far_ = 0;         // min(kFarFactor · M, kEmbreeRange / 2) at the last commit
    bool in_range_ = true;  // kEmbreeMinScale <= M and the padded boxes within kEmbreeRange: Embree holds them
    bool dirty_ = true;
    std::uint64_t commits_ = 0;
};

template <class Count, class Visit>
void EmbreeBoxes::traverse(const Segment& s, Count& count, Visit&& visit) {
    traverse_or_scan(s, objects_, count, visit,
                     [&](ExactCollector& collect) { return embree_query(s, collect, StopsAtFirstHit<Visit>); });
}

}  // namespace rcb

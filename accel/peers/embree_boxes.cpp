#include "accel/peers/embree_boxes.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <embree3/rtcore.h>
#include <tbb/task_arena.h>

namespace rcb {

struct EmbreeBoxes::Device {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    RTCGeometry geometry = nullptr;
    unsigned geometry_id = 0;  // 0 or 1: a policy rebuild attaches a fresh geometry under the other
    std::unique_ptr<tbb::task_arena> arena;
    /// Bytes Embree holds, from its memory monitor callback.
    std::atomic<std::int64_t> bytes{0};
    std::string error;  // the last error Embree reported

    ~Device() {
        if (geometry) rtcReleaseGeometry(geometry);
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

namespace {

struct QueryContext {
    RTCIntersectContext base;  // first member: Embree hands our pointer back to the callbacks
    ExactCollector* collect;
};

void bounds_callback(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const EmbreeBoxes*>(args->geometryUserPtr);
    const Aabb& b = self->box_at(args->primID);
    const float pad = self->pad();
    RTCBounds* o = args->bounds_o;
    o->lower_x = b.min.x - pad, o->lower_y = b.min.y - pad, o->lower_z = b.min.z - pad;
    o->upper_x = b.max.x + pad, o->upper_y = b.max.y + pad, o->upper_z = b.max.z + pad;
}

/// rtcIntersect1's callback (all and closest hits): records a hit without committing it, so
/// Embree keeps traversing; the decision is the exact collector's.
void intersect_callback(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    ExactCollector& collect = *reinterpret_cast<QueryContext*>(args->context)->collect;
    const ExactCollector::Offer offer = collect.offer(args->primID);
    if (offer == ExactCollector::Offer::miss) return;
    float& tfar = reinterpret_cast<RTCRayHit*>(args->rayhit)->ray.tfar;
    if (offer == ExactCollector::Offer::stop) {
        tfar = -std::numeric_limits<float>::infinity();  // culls every remaining node
    } else if (collect.has_limit()) {
        // The padded bounds are entered before the box itself, so a box entered at or before the
        // nearest hit is still reached (the padding's exactness argument, docs/structures.md).
        tfar = std::min(tfar, collect.limit());
    }
}

/// rtcOccluded1's callback (any hit): the exact hit that ends the query marks the ray occluded
/// (tfar = -inf), and Embree ends its traversal there.
void occluded_callback(const RTCOccludedFunctionNArguments* args) {
    if (!args->valid[0]) return;
    ExactCollector& collect = *reinterpret_cast<QueryContext*>(args->context)->collect;
    if (collect.offer(args->primID) == ExactCollector::Offer::stop)
        reinterpret_cast<RTCRay*>(args->ray)->tfar = -std::numeric_limits<float>::infinity();
}

void error_callback(void* user, RTCError code, const char* message) {
    auto* d = static_cast<EmbreeBoxes::Device*>(user);
    d->error = "embree error " + std::to_string(int(code)) + ": " + (message ? message : "");
}

bool memory_callback(void* user, ssize_t bytes, bool) {
    static_cast<EmbreeBoxes::Device*>(user)->bytes += bytes;
    return true;
}

/// A user geometry of no primitives yet with the peer's callbacks, committed.
RTCGeometry new_user_geometry(RTCDevice device, EmbreeBoxes* self, RTCBuildQuality quality) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, 0);
    rtcSetGeometryUserData(g, self);
    rtcSetGeometryBoundsFunction(g, bounds_callback, nullptr);
    rtcSetGeometryIntersectFunction(g, intersect_callback);
    rtcSetGeometryOccludedFunction(g, occluded_callback);
    rtcSetGeometryBuildQuality(g, quality);
    rtcCommitGeometry(g);
    return g;
}

}  // namespace

EmbreeBoxes::EmbreeBoxes() : EmbreeBoxes(Params{}) {}

EmbreeBoxes::EmbreeBoxes(const Params& params)
    : params_(params),
      quality_(parse_choice<Quality>(kQualityChoices, params.quality, "embree quality")),
      device_(std::make_unique<Device>()) {
    Device& d = *device_;
    d.device = rtcNewDevice(nullptr);
    if (!d.device)
        throw std::runtime_error("embree: rtcNewDevice failed (error " +
                                 std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(d.device, error_callback, &d);
    rtcSetDeviceMemoryMonitorFunction(d.device, memory_callback, &d);
    d.scene = rtcNewScene(d.device);
    const bool low = quality_ == Quality::low;
    rtcSetSceneBuildQuality(d.scene, low || params_.refit ? RTC_BUILD_QUALITY_LOW : RTC_BUILD_QUALITY_MEDIUM);
    if (params_.refit) rtcSetSceneFlags(d.scene, RTC_SCENE_FLAG_DYNAMIC);
    d.geometry = new_user_geometry(
        d.device, this,
        params_.refit ? RTC_BUILD_QUALITY_REFIT : (low ? RTC_BUILD_QUALITY_LOW : RTC_BUILD_QUALITY_MEDIUM));
    rtcAttachGeometryByID(d.scene, d.geometry, d.geometry_id);
    d.arena = std::make_unique<tbb::task_arena>(params_.threads);
    if (!d.error.empty()) throw std::runtime_error("embree: " + d.error);
    set_cast_threads(params_.cast_threads);
}

EmbreeBoxes::~EmbreeBoxes() = default;

void EmbreeBoxes::build(std::span<const Object> objects) {
    if (params_.refit && commits_ > 0) fresh_geometry();  // built anew, not refitted from the old contents
    objects_.clear();
    objects_.reserve(objects.size());
    for (const Object& o : objects) insert(o);
    dirty_ = true;
    commit();
}

void EmbreeBoxes::insert(const Object& o) {
    objects_.insert(o);
    dirty_ = topology_changed_ = true;
}

void EmbreeBoxes::remove(Uid uid) {
    objects_.remove(uid);
    dirty_ = topology_changed_ = true;
}

void EmbreeBoxes::move(const Object& o) {
    objects_.move(o);
    dirty_ = true;
}

void EmbreeBoxes::commit() {
    if (!dirty_) return;
    float m = 0;
    for (const Aabb& b : objects_.layout().all())
        m = std::max({m, std::abs(b.min.x), std::abs(b.min.y), std::abs(b.min.z), std::abs(b.max.x), std::abs(b.max.y),
                      std::abs(b.max.z)});
    m = std::max(m, std::numeric_limits<float>::min());
    pad_ = params_.robust ? kPadRelative * m : 0.0f;
    in_range_ = m >= kEmbreeMinScale && m + pad_ <= kEmbreeRange;
    far_ = in_range_ ? std::min(kFarFactor * m, kEmbreeRange / 2) : 0.0f;
    Device& d = *device_;
    const unsigned count = in_range_ ? static_cast<unsigned>(objects_.size()) : 0u;
    // Without refit Embree rebuilds at every commit; with it, it rebuilds when the primitive count
    // changed, and the policy (see the header) forces a rebuild by a fresh geometry otherwise.
    bool rebuild = !params_.refit || commits_ == 0 || count != committed_count_;
    ++since_rebuild_;
    if (!rebuild && ((params_.rebuild_on_inserts && topology_changed_) ||
                     (params_.rebuild_every > 0 && since_rebuild_ >= std::uint64_t(params_.rebuild_every)))) {
        fresh_geometry();
        rebuild = true;
    }
    if (rebuild) {
        ++rebuilds_;
        since_rebuild_ = 0;
    }
    topology_changed_ = false;
    committed_count_ = count;
    rtcSetGeometryUserPrimitiveCount(d.geometry, count);
    rtcCommitGeometry(d.geometry);  // the bounds changed: Embree calls bounds_callback again
    d.arena->execute([&] { rtcCommitScene(d.scene); });
    if (!d.error.empty()) throw std::runtime_error("embree: " + d.error);
    dirty_ = false;
    ++commits_;
}

void EmbreeBoxes::fresh_geometry() {
    Device& d = *device_;
    RTCGeometry fresh = new_user_geometry(d.device, this, RTC_BUILD_QUALITY_REFIT);
    const unsigned id = 1 - d.geometry_id;
    rtcAttachGeometryByID(d.scene, fresh, id);
    rtcDetachGeometry(d.scene, d.geometry_id);
    rtcReleaseGeometry(d.geometry);
    d.geometry = fresh;
    d.geometry_id = id;
}

bool EmbreeBoxes::embree_query(const Segment& s, ExactCollector& collect, bool occluded) const {
    if (!in_range_) return false;
    const Vec3 d = s.delta();
    if (d.x == 0 && d.y == 0 && d.z == 0) return false;
    if (!within_reach(s, far_)) return false;
    QueryContext ctx;
    rtcInitIntersectContext(&ctx.base);
    ctx.collect = &collect;
    RTCRayHit rh;
    rh.ray.org_x = s.p0.x, rh.ray.org_y = s.p0.y, rh.ray.org_z = s.p0.z;
    rh.ray.dir_x = d.x, rh.ray.dir_y = d.y, rh.ray.dir_z = d.z;
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = 1.0f;
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    if (occluded)
        rtcOccluded1(device_->scene, &ctx.base, &rh.ray);
    else
        rtcIntersect1(device_->scene, &ctx.base, &rh);
    return true;
}

std::size_t EmbreeBoxes::memory_bytes() const {
    const std::size_t bytes = objects_.memory_bytes() + scratch_bytes();
    const std::int64_t embree = device_->bytes.load();
    return bytes + sizeof(*this) + std::size_t(std::max<std::int64_t>(0, embree));
}

nlohmann::json EmbreeBoxes::stats() const {
    return {{"commits", commits_},
            {"rebuilds", rebuilds_},
            {"pad", pad_},
            {"embree_bytes", device_->bytes.load()},
            {"in_range", in_range_}};
}

void EmbreeBoxes::check() const {
    const std::size_t n = objects_.size();
    objects_.check("embree");
    if (dirty_ || n == 0 || !in_range_) return;
    // Embree's scene bounds must enclose every (padded) box we gave it.
    RTCBounds sb;
    rtcGetSceneBounds(device_->scene, &sb);
    for (std::size_t i = 0; i < n; ++i) {
        const Aabb& b = objects_.box(i);
        if (b.min.x < sb.lower_x || b.min.y < sb.lower_y || b.min.z < sb.lower_z || b.max.x > sb.upper_x ||
            b.max.y > sb.upper_y || b.max.z > sb.upper_z)
            broken_invariant("embree", "scene bounds do not enclose uid " + std::to_string(objects_.uid(i)));
    }
}

}  // namespace rcb

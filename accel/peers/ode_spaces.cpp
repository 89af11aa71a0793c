#include "accel/peers/ode_spaces.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <mutex>
#include <string>

#include <ode/ode.h>

namespace rcb {
namespace {

/// Bytes ODE holds, allocated minus freed on this thread: ODE's allocation hooks pass the size to
/// both, so the balance is exact. An instance adds the change across each of its own calls.
thread_local std::int64_t ode_live_bytes = 0;

void* ode_alloc(dsizeint size) {
    ode_live_bytes += std::int64_t(size);
    return std::malloc(size ? size : 1);
}
void* ode_realloc(void* ptr, dsizeint old_size, dsizeint new_size) {
    ode_live_bytes += std::int64_t(new_size) - std::int64_t(old_size);
    return std::realloc(ptr, new_size ? new_size : 1);
}
void ode_free(void* ptr, dsizeint size) {
    ode_live_bytes -= std::int64_t(size);
    std::free(ptr);
}

/// ODE's library and per-thread data, once each (dInitODE2, dAllocateODEDataForThread).
void ode_ready() {
    static std::once_flag library;
    std::call_once(library, [] {
        dSetAllocHandler(ode_alloc);
        dSetReallocHandler(ode_realloc);
        dSetFreeHandler(ode_free);
        dInitODE2(0);
    });
    thread_local const bool thread = dAllocateODEDataForThread(dAllocateMaskAll) != 0;
    if (!thread) throw std::runtime_error("ODE: dAllocateODEDataForThread failed");
}

std::uint32_t slot_of(dGeomID geom) { return std::uint32_t(reinterpret_cast<std::uintptr_t>(dGeomGetData(geom))); }

}  // namespace

/// ODE's objects of one instance, and the bytes ODE allocated for them.
struct OdeSpace::Ode {
    dSpaceID space = nullptr;
    dGeomID ray = nullptr;
    std::vector<dGeomID> geoms;  // slot-indexed, as objects_
    std::int64_t bytes = 0;
    double center[2] = {0, 0}, extents[2] = {1, 1};  // the quadtree's root block

    ~Ode() { clear(); }
    void clear() {
        if (space) dSpaceDestroy(space);  // destroys its geoms too (cleanup mode, ODE's default)
        if (ray) dGeomDestroy(ray);
        space = nullptr;
        ray = nullptr;
        geoms.clear();
    }
};

namespace {

/// Adds what ODE allocates or frees during one of the instance's calls to the instance's bytes; a
/// call made inside another (build's inserts) is counted by the outer one only.
thread_local int ode_call_depth = 0;

class OdeBytes {
public:
    explicit OdeBytes(std::int64_t& bytes) : bytes_(bytes), start_(ode_live_bytes) { ++ode_call_depth; }
    ~OdeBytes() {
        if (--ode_call_depth == 0) bytes_ += ode_live_bytes - start_;
    }
    OdeBytes(const OdeBytes&) = delete;
    OdeBytes& operator=(const OdeBytes&) = delete;

private:
    std::int64_t& bytes_;
    std::int64_t start_;
};

/// dSpaceCollide2's callback: the geom that is not the ray is offered to the exact collector. ODE
/// cannot be stopped mid-query, so after a stop the collector declines the rest untested.
void near_callback(void* data, dGeomID a, dGeomID b) {
    const dGeomID object = dGeomGetClass(a) == dRayClass ? b : a;
    static_cast<ExactCollector*>(data)->offer(slot_of(object));
}

}  // namespace

OdeSpace::OdeSpace(Kind kind, int depth, int up, double root_margin)
    : kind_(kind), depth_(depth), root_margin_(root_margin), ode_(std::make_unique<Ode>()) {
    // ODE's z is the scene's `up`; its x and y the other two in order (a cyclic permutation).
    for (int a = 0; a < 3; ++a) perm_[a] = (up + 1 + a) % 3;
    ode_ready();
}

OdeSpace::~OdeSpace() = default;

void OdeSpace::build(std::span<const Object> objects) {
    OdeBytes bytes(ode_->bytes);
    ode_->clear();
    objects_.clear();
    scale_ = 0;
    Aabb bounds = Aabb::empty();
    for (const Object& o : objects) {
        scale_ = std::max(scale_, largest_coordinate(o.box));
        bounds = merge(bounds, o.box);
    }
    scale_ = std::max(scale_, std::numeric_limits<float>::min());
    if (kind_ == Kind::quadtree) {
        // The root block: the build's bounds in ODE's x-y plane (the quadtree ignores z) grown by
        // root_margin of their size on each side; later objects beyond it live in the root.
        for (int a = 0; a < 2; ++a) {
            const bool any = !objects.empty();
            const double size = any ? hi(bounds, a) - lo(bounds, a) : 0.0;
            ode_->center[a] = any ? 0.5 * (lo(bounds, a) + hi(bounds, a)) : 0.0;
            ode_->extents[a] = any ? std::max((0.5 + root_margin_) * size, 1e-30) : 1.0;
        }
        dVector3 center = {ode_->center[0], ode_->center[1], 0, 0};
        dVector3 extents = {ode_->extents[0], ode_->extents[1], 1, 0};
        ode_->space = dQuadTreeSpaceCreate(nullptr, center, extents, depth_);
    } else if (kind_ == Kind::hash) {
        ode_->space = dHashSpaceCreate(nullptr);
    } else {
        ode_->space = dSweepAndPruneSpaceCreate(nullptr, dSAP_AXES_XZY);
    }
    ode_->ray = dCreateRay(nullptr, 1);
    objects_.reserve(objects.size());
    ode_->geoms.reserve(objects.size());
    for (const Object& o : objects) insert(o);
}

void OdeSpace::set_geom(std::uint32_t slot) {
    const Aabb& b = objects_.box(slot);
    const double pad = this->pad();
    double length[3], center[3];
    for (int a = 0; a < 3; ++a) {
        length[a] = hi(b, a) - lo(b, a) + 2 * pad;
        center[a] = 0.5 * (lo(b, a) + hi(b, a));
    }
    dGeomID& geom = ode_->geoms[slot];
    if (!geom) {
        geom = dCreateBox(ode_->space, length[0], length[1], length[2]);
    } else {
        dGeomBoxSetLengths(geom, length[0], length[1], length[2]);
    }
    dGeomSetPosition(geom, center[0], center[1], center[2]);
    dGeomSetData(geom, reinterpret_cast<void*>(std::uintptr_t(slot)));
}

void OdeSpace::cover(const Aabb& box) {
    const float m = largest_coordinate(box);
    if (m <= scale_) return;
    scale_ = std::max(2 * m, std::numeric_limits<float>::min());
    ++repads_;
    for (std::uint32_t i = 0; i < objects_.size(); ++i) set_geom(i);
}

void OdeSpace::insert(const Object& o) {
    OdeBytes bytes(ode_->bytes);
    if (!ode_->space) build({});
    const std::uint32_t slot = objects_.insert(o);
    ode_->geoms.push_back(nullptr);
    cover(o.box);
    set_geom(slot);
}

void OdeSpace::remove(Uid uid) {
    OdeBytes bytes(ode_->bytes);
    const std::uint32_t slot = objects_.remove(uid);
    dGeomDestroy(ode_->geoms[slot]);       // leaves its space
    if (slot != ode_->geoms.size() - 1) {  // the last slot's object moved into `slot`
        ode_->geoms[slot] = ode_->geoms.back();
        dGeomSetData(ode_->geoms[slot], reinterpret_cast<void*>(std::uintptr_t(slot)));
    }
    ode_->geoms.pop_back();
}

void OdeSpace::move(const Object& o) {
    OdeBytes bytes(ode_->bytes);
    const std::uint32_t slot = objects_.move(o);
    cover(o.box);
    set_geom(slot);
}

void OdeSpace::commit() {
    if (!ode_->space) return;
    OdeBytes bytes(ode_->bytes);  // re-filing may grow the space's lists
    dSpaceClean(ode_->space);
}

bool OdeSpace::ode_query(const Segment& s, ExactCollector& collect) {
    if (!within_reach(s, kFarFactor * scale_)) return false;
    double origin[3], d[3];
    for (int a = 0; a < 3; ++a) {
        origin[a] = double(s.p0[perm_[a]]);
        d[a] = double(s.p1[perm_[a]]) - origin[a];
    }
    const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (!(length > 0)) return false;
    OdeBytes bytes(ode_->bytes);
    dGeomRaySet(ode_->ray, origin[0], origin[1], origin[2], d[0], d[1], d[2]);
    dGeomRaySetLength(ode_->ray, length);
    dSpaceCollide2(ode_->ray, reinterpret_cast<dGeomID>(ode_->space), &collect, near_callback);
    // The hash and sweep-and-prune spaces scan every geom's AABB (see the header).
    if (kind_ != Kind::quadtree) collect.add_tests(objects_.size());
    return true;
}

std::size_t OdeSpace::memory_bytes() const {
    const std::size_t bytes = objects_.memory_bytes() + ode_->geoms.capacity() * sizeof(dGeomID);
    return bytes + sizeof(*this) + sizeof(Ode) + std::size_t(std::max<std::int64_t>(0, ode_->bytes));
}

nlohmann::json OdeSpace::stats() const {
    nlohmann::json out = {{"pad", pad()}, {"repads", repads_}, {"ode_bytes", ode_->bytes}};
    if (kind_ == Kind::quadtree) {
        out["depth"] = depth_;
        out["up"] = std::string(1, "xyz"[perm_[2]]);
        out["root_center"] = {ode_->center[0], ode_->center[1]};
        out["root_extents"] = {ode_->extents[0], ode_->extents[1]};
    }
    return out;
}

void OdeSpace::check(const char* who) const {
    const std::size_t n = objects_.size();
    objects_.check(who);
    if (ode_->geoms.size() != n) broken_invariant(who, "slot arrays differ in size");
    if (n == 0) return;
    if (std::size_t(dSpaceGetNumGeoms(ode_->space)) != n)
        broken_invariant(who, "space holds " + std::to_string(dSpaceGetNumGeoms(ode_->space)) + " geoms for " +
                                  std::to_string(n) + " objects");
    const double half_pad = 0.5 * pad();
    for (std::uint32_t i = 0; i < n; ++i) {
        const dGeomID geom = ode_->geoms[i];
        if (!geom || slot_of(geom) != i || dGeomGetSpace(geom) != ode_->space)
            broken_invariant(who, "geom of slot " + std::to_string(i) + " does not point back");
        dReal aabb[6];
        dGeomGetAABB(geom, aabb);
        const Aabb& b = objects_.box(i);
        // The geom's AABB must enclose the box with the padding (the exactness argument needs it).
        for (int a = 0; a < 3; ++a)
            if (aabb[2 * a] > lo(b, a) - half_pad || aabb[2 * a + 1] < hi(b, a) + half_pad)
                broken_invariant(who,
                                 "geom of uid " + std::to_string(objects_.uid(i)) + " does not enclose its padded box");
    }
}

}  // namespace rcb

#pragma once
/// Peer: the Open Dynamics Engine's collision spaces (ODE 0.16, Debian's libode) queried the way an
/// ODE program asks "what does this segment touch?": the segment is a ray geom, and
/// dSpaceCollide2(ray, space) calls back for every object geom whose AABB overlaps the ray's AABB.
/// Each object is a box geom of its padded box; every candidate the space reports is decided by
/// rcb's exact slab test on the unpadded box, so hits, t and the touching rule equal every rcb
/// structure's (the padding covers ODE's double-precision AABB arithmetic). What the sources do
/// for this query:
///   ode_quadtree  dQuadTreeSpace: a fixed quadtree of `depth` levels over ODE's x and y, its
///                 z the up axis (collision_quadtreespace.cpp: AXIS0 0, AXIS1 1, UP 2); the scene's
///                 `up` axis is mapped to ODE's z by a permutation of coordinates (exact: no
///                 arithmetic), so the quadtree divides the ground plane. Its root is the build's
///                 bounds in that plane grown by `root_margin` of their size on each side; an object
///                 lives in the smallest block that holds its AABB (the root when none does).
///                 dSpaceCollide2 prunes blocks by the ray's AABB against the block's rectangle,
///                 then tests each geom's AABB.
///   ode_hash      dHashSpace: its multi-resolution hash serves space-wide collide() only;
///                 dSpaceCollide2 with a single geom scans every geom's AABB linearly (the source
///                 says so: "this could take advantage of the hash structure ... but it does not
///                 yet").
///   ode_sap       dSweepAndPruneSpace: its sorted axes serve space-wide collide() only;
///                 dSpaceCollide2 with a single geom scans every geom's AABB linearly, as the hash
///                 space does (collision_sapspace.cpp, dxSAPSpace::collide2: "just a simple N^2
///                 implementation").
/// Every space files moved geoms lazily: a move marks the geom dirty, and the space re-files its
/// dirty geoms (recomputes their AABBs, moves them between blocks or lists) in cleanGeoms, which
/// the next collide or collide2 calls. commit() calls it, dSpaceClean, as an ODE program's step
/// does through dSpaceCollide before its queries, so the work lands in the update, not in the first
/// ray. All three test against the ray's whole AABB, computed once per dSpaceCollide2 call, and
/// the call has no exit: a closest-hit query cannot shorten the ray at a hit (the ray's ClosestHit flag is read by
/// the trimesh collider only, collision.h), and an any-hit query only tests no geom after its
/// first hit (exact_collector.h). Rays ODE's AABBs cannot bound exactly (zero length, non-finite,
/// beyond kFarFactor × the scene's scale) go to an exact scan. Counters: N_RB = the exact tests of
/// the geoms the space reports, plus for the hash and sweep-and-prune spaces their scan of every geom's AABB (the
/// quadtree's own AABB tests in the blocks it visits are not exposed), plus scan tests; N_T is not
/// exposed (0), as for Embree. Memory: rcb's arrays plus the bytes ODE allocated for this instance
/// (counted through ODE's allocation hooks while the instance runs; one instance per thread at a
/// time). Rays are cast on one thread: these peers take no `cast_threads`. ODE runs collision
/// detection on several threads only "for separate spaces" (CHANGELOG.txt; CMakeLists.txt,
/// ODE_WITH_OU); every collide2 of one space writes to it (dxSpace::lock_count++ and cleanGeoms,
/// collision_space.cpp dxHashSpace::collide2, collision_quadtreespace.cpp
/// dxQuadTreeSpace::collide2, collision_sapspace.cpp dxSAPSpace::collide2; lock_count is a plain
/// int, collision_kernel.h), and the ray geom is one object whose position and length each query
/// sets.

#include <cstdint>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "accel/common/exact_collector.h"
#include "accel/common/slot_boxes.h"
#include "accel/interface/params.h"
#include "accel/interface/structure.h"

namespace rcb {

/// What both ODE peers share: the space, its geoms (slot-indexed like the table) and the query.
class OdeSpace {
public:
    enum class Kind : std::uint8_t { quadtree, hash, sap };

    static constexpr float kFarFactor = 16.0f;
    static constexpr float kPadRelative = 1e-6f;

    /// `up`: the scene axis mapped to ODE's z (the quadtree's up axis); `root_margin`: the
    /// quadtree root's growth beyond the build's bounds, in their size, on each side.
    OdeSpace(Kind kind, int depth, int up = 2, double root_margin = 0);
    ~OdeSpace();
    OdeSpace(const OdeSpace&) = delete;
    OdeSpace& operator=(const OdeSpace&) = delete;

    void build(std::span<const Object> objects);
    void insert(const Object& object);
    void remove(Uid uid);
    void move(const Object& object);
    void commit();  ///< dSpaceClean: the dirty geoms re-filed now
    std::size_t size() const { return objects_.size(); }
    std::size_t memory_bytes() const;
    nlohmann::json stats() const;
    void check(const char* who) const;

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        traverse_or_scan(s, objects_, count, visit, [&](ExactCollector& collect) { return ode_query(s, collect); });
    }

private:
    struct Ode;
    /// dSpaceCollide2 of the segment's ray against the space, every geom it reports offered to
    /// `collect`; false when the segment needs the exact fallback.
    bool ode_query(const Segment& s, ExactCollector& collect);
    void set_geom(std::uint32_t slot);  ///< the slot's geom to its padded box
    void cover(const Aabb& box);        ///< grows the scale (re-pads every geom) when `box` lies beyond it
    float pad() const { return kPadRelative * scale_; }
    /// The box's bounds on ODE's axis `a` (the scene's axis perm_[a]).
    double lo(const Aabb& b, int a) const { return double(b.min[perm_[a]]); }
    double hi(const Aabb& b, int a) const { return double(b.max[perm_[a]]); }

    Kind kind_;
    int depth_;
    int perm_[3] = {0, 1, 2};  ///< ODE's axis a is the scene's axis perm_[a]
    double root_margin_;
    std::unique_ptr<Ode> ode_;
    SlotBoxes objects_;
    float scale_ = 0;
    std::uint64_t repads_ = 0;
};

/// An ODE space as a structure: everything forwarded to the OdeSpace it holds.
template <class Derived>
class OdePeer : public StructureBase<Derived> {
public:
    void build(std::span<const Object> objects) override { space_.build(objects); }
    void insert(const Object& object) override { space_.insert(object); }
    void remove(Uid uid) override { space_.remove(uid); }
    void move(const Object& object) override { space_.move(object); }
    void commit() override { space_.commit(); }
    std::size_t size() const override { return space_.size(); }
    std::size_t memory_bytes() const override { return space_.memory_bytes() + sizeof(Derived) - sizeof(OdeSpace); }
    nlohmann::json stats() const override { return space_.stats(); }
    void check() const override { space_.check(name_); }

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        space_.traverse(s, count, std::forward<Visit>(visit));
    }

protected:
    OdePeer(OdeSpace::Kind kind, int depth, const char* name, int up = 2, double root_margin = 0)
        : space_(kind, depth, up, root_margin), name_(name) {}

private:
    OdeSpace space_;
    const char* name_;  ///< the registry's name, for broken_invariant
};

/// ODE's quadtree space (see above).
class OdeQuadTree : public OdePeer<OdeQuadTree> {
public:
    /// Params::up's choices, in the order of the scene's axis they name.
    static constexpr const char* kUpChoices = "x,y,z";
    enum class Up : std::uint8_t { x, y, z };
    struct Params {
        int depth = 6;
        std::string up = "y";
        double root_margin = 0.5;
        static constexpr auto fields() {
            return std::tuple{
                Field{"depth", &Params::depth, 1, 9,
                      "levels of dQuadTreeSpace's block tree below its root (4^depth leaf blocks over the root)"},
                Field{"up", &Params::up, 0, 0,
                      "the scene's up axis, mapped to ODE's z so that the quadtree divides the other two (rcbench's "
                      "physics scenes are y-up; Quake maps z-up)",
                      choices(kUpChoices)},
                Field{"root_margin", &Params::root_margin, 0, 4,
                      "the root block extends the build's bounds by this share of their size on each side (objects "
                      "beyond it live in the root block)"}};
        }
    };
    OdeQuadTree() : OdeQuadTree(Params{}) {}
    explicit OdeQuadTree(const Params& p)
        : OdePeer(OdeSpace::Kind::quadtree, p.depth, "ode_quadtree",
                  int(parse_choice<Up>(kUpChoices, p.up, "ode_quadtree up")), p.root_margin) {}
};

/// ODE's hash space (see above: its segment query is a linear scan of the geoms' AABBs; its
/// levels, dHashSpaceSetLevels, serve collide() only).
class OdeHash : public OdePeer<OdeHash> {
public:
    struct Params {
        static constexpr auto fields() { return std::tuple{}; }
    };
    OdeHash() : OdeHash(Params{}) {}
    explicit OdeHash(const Params&) : OdePeer(OdeSpace::Kind::hash, 0, "ode_hash") {}
};

/// ODE's sweep-and-prune space (see above: its segment query is a linear scan of the geoms'
/// AABBs; its axis order serves collide() only).
class OdeSap : public OdePeer<OdeSap> {
public:
    struct Params {
        static constexpr auto fields() { return std::tuple{}; }
    };
    OdeSap() : OdeSap(Params{}) {}
    explicit OdeSap(const Params&) : OdePeer(OdeSpace::Kind::sap, 0, "ode_sap") {}
};

}  // namespace rcb

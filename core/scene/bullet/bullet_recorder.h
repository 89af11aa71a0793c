#pragma once
/// Recording a Bullet game's own workload (rcbench::bullet_recorder): every collision object of a
/// btCollisionWorld, step by step, and the rays the game casts through the world, written as a
/// `.rcbscene` that every rcbench command replays (`simulate`, `advise`, experiments).
///
///     rcb::BulletRecorder rec(*world, "game.rcbscene");   // frame 0: the world as it is now
///     world->stepSimulation(dt);  rec.step();             // after each step: its changes
///     rec.ray_test(from, to, callback);                   // instead of world->rayTest(from, to, callback)
///
/// Objects. step() walks the world's collision objects (btCollisionWorld::getCollisionObjectArray)
/// and records, against the last step, the objects added (insert), gone (remove) and whose shape or
/// transform changed (move). Each object keeps one uid from the step it is first seen until it
/// leaves the world (uid(object) names it); an object whose collision shape is replaced gets a new
/// uid (a remove and an insert). Sleeping and static objects do not change, so they are not moved.
/// The recorded shape is Bullet's, so rcbench's shapes level (query_level.h) tests what Bullet's
/// narrow phase tests:
///
///     btBoxShape      an obb at the object's transform, half extents getHalfExtentsWithMargin():
///                     the margin lies inside the extents the box was made with (btBoxShape.h,
///                     btBoxShape::btBoxShape subtracts it from the implicit dimensions and
///                     getHalfExtentsWithMargin adds it back), so these are the game's half extents
///                     times the local scaling
///     btSphereShape   a sphere, getRadius() (the margin is the radius: btSphereShape.h)
///     btCapsuleShape  a capsule along its up axis (getUpAxis), half height getHalfHeight(), radius
///                     getRadius() (btCapsuleShape.h; X and Z capsules too)
///     anything else   a box, its world AABB (btCollisionShape::getAabb at the object's transform,
///                     margin included): exact for the broad phase, but at the shapes level rcbench
///                     then tests the box, not the cone, hull, compound or mesh inside it
///
/// A shaped object's box is the shape's tight bounds (shape_bounds), not the broadphase AABB that
/// Bullet keeps, which btCollisionWorld::updateSingleAabb fattens by the contact breaking threshold
/// (and, for moving bodies, by the step's motion): rcbench's structures hold exact boxes.
///
/// Rays. ray_test() records the segment from `from` to `to` and casts it with
/// btCollisionWorld::rayTest, so the game's callback gets exactly what it got before. The query
/// kind is the callback's: closest for btCollisionWorld::ClosestRayResultCallback (and classes
/// derived from it), all hits for AllHitsRayResultCallback and for any other callback (Bullet calls
/// addSingleResult for every hit before the callback's own filter); the overload taking a kind
/// says it explicitly. Collision filter groups and masks (needsCollision) are not recorded: rcbench
/// casts every ray against every object.
///
/// Frames. A recorded frame is one step's changes and then the rays cast after it, the order in
/// which rcbench replays a frame (recorder.h: "Replay order"): step() ends the frame before it (if
/// it had a step or rays) and records its changes into a new one. Rays cast before the first
/// step() go into frame 1, against the world of frame 0.
///
/// Where rcbench's answer can differ from Bullet's (docs/own-structure.md, "Recording a Bullet
/// game", with the measured agreement). Bullet tests convex shapes by conservative advancement
/// (btSubsimplexConvexCast::calcTimeOfImpact), which stops once the ray's point is within
/// sqrt(1e-4) = 0.01 units of the shape (its squared-distance epsilon); rcbench tests the exact shape:
///   - ties: two objects entered within that tolerance of each other (a box resting on the ground,
///     touching boxes, a ray through their contact). Bullet keeps the first one its broadphase
///     visits (btCollisionWorld::rayTestSingleInternal adds a hit only at a fraction strictly below
///     the best so far), rcbench the smaller entry t, then the smaller uid (structure.h);
///   - grazes: a ray passing within that tolerance of a shape, which Bullet may report as a hit;
///   - a ray that starts inside a convex object: rcbench reports it at t = 0, Bullet reports no hit
///     (the cast's normal is zero there, and btSubsimplexConvexCast then returns no impact).
///
/// Errors are rcb::InputError, as rcb::Recorder's (recorder.h), naming the file and the object:
/// an unwritable path at construction (before anything is recorded), an object whose transform or
/// AABB is not finite or reaches beyond ±1e15 (a btStaticPlaneShape's AABB is all of space: give the
/// ground a btBoxShape), a ray with such an end point. The file is written by close() or the
/// destructor, atomically; nothing else is written. Not thread-safe, as Bullet's world is not.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include <BulletCollision/CollisionDispatch/btCollisionWorld.h>

#include "core/scene/recorder.h"
#include "core/scene/shape.h"

namespace rcb {

class BulletRecorder {
public:
    /// Records every object of `world` as frame 0. `world` must outlive the recorder.
    BulletRecorder(const btCollisionWorld& world, std::string path, const std::string& meta_json = "{}");
    /// Writes the file if close() was not called (a failure is one line on stderr, as ~Recorder).
    ~BulletRecorder();
    BulletRecorder(const BulletRecorder&) = delete;
    BulletRecorder& operator=(const BulletRecorder&) = delete;

    /// After each step of the world: ends the previous frame and records this step's changes.
    void step();
    /// world.rayTest(from, to, callback), recorded with the callback's query kind (above).
    void ray_test(const btVector3& from, const btVector3& to, btCollisionWorld::RayResultCallback& callback);
    /// The same with the query kind given.
    void ray_test(const btVector3& from, const btVector3& to, btCollisionWorld::RayResultCallback& callback,
                  QueryKind kind);
    /// Ends the last frame and writes the file (Recorder::close).
    void close();

    /// The uid `object` is recorded under, if it was in the world at the last step().
    std::optional<Uid> uid(const btCollisionObject* object) const;
    /// What `object` is recorded as (above) under `uid`; InputError naming `where` when it cannot be.
    static Object object_of(const btCollisionObject& object, Uid uid, const std::string& where);
    /// The frame the next ray goes into, the objects recorded live, the recorder underneath.
    std::uint32_t frame() const;
    std::size_t live_count() const;
    const Recorder& recorder() const;

private:
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace rcb

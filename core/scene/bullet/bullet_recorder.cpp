#include "core/scene/bullet/bullet_recorder.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <utility>
#include <vector>

#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletCollision/CollisionShapes/btCapsuleShape.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <LinearMath/btScalar.h>
#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/scene/recording_io.h"

namespace rcb {

/// The objects seen at the last step, by pointer, and whether the current frame has a step or rays
/// (header: "Frames").
struct BulletRecorder::State {
    struct Seen {
        Uid uid;
        const btCollisionShape* shape;  // a new shape is a new object (header: "Objects")
        Object object;                  // as last recorded
        std::uint64_t stamp;            // the last step() that saw it
    };
    const btCollisionWorld* world;
    Recorder recorder;
    std::unordered_map<const btCollisionObject*, Seen> seen;
    std::uint64_t stamp = 0;
    Uid next_uid = 0;
    bool frame_used = false;  // the current frame has had a step() or a ray

    State(const btCollisionWorld& w, std::string path, const std::string& meta)
        : world(&w), recorder(std::move(path), meta) {}

    std::string where(int index) const {
        return "recorder " + recorder.path() + ": frame " + std::to_string(recorder.frame()) + ": collision object " +
               std::to_string(index);
    }

    /// One pass over the world's objects into the current frame's changes. Every object is
    /// converted first, so an object that cannot be recorded leaves the step unrecorded.
    void record_objects() {
        struct Now {
            const btCollisionObject* object;
            Object recorded;
            bool fresh;  // not seen before, or with a new shape: a new uid
        };
        std::vector<Now> now;
        Uid uid = next_uid;
        const btCollisionObjectArray& objects = world->getCollisionObjectArray();
        for (int i = 0; i < objects.size(); ++i) {
            auto it = seen.find(objects[i]);
            const bool fresh = it == seen.end() || it->second.shape != objects[i]->getCollisionShape();
            now.push_back({objects[i], object_of(*objects[i], fresh ? uid++ : it->second.uid, where(i)), fresh});
        }
        next_uid = uid;
        ++stamp;
        for (const Now& n : now) {
            auto it = seen.find(n.object);
            if (n.fresh && it != seen.end()) {  // a new shape: the old object leaves
                recorder.remove(it->second.uid);
                seen.erase(it);
            }
            if (n.fresh) {
                put(n.recorded, true);
                seen.emplace(n.object, Seen{n.recorded.uid, n.object->getCollisionShape(), n.recorded, stamp});
                continue;
            }
            if (!(n.recorded == it->second.object)) put(n.recorded, false);
            it->second.object = n.recorded;
            it->second.stamp = stamp;
        }
        std::vector<Uid> gone;
        for (auto it = seen.begin(); it != seen.end();) {
            if (it->second.stamp == stamp) {
                ++it;
                continue;
            }
            gone.push_back(it->second.uid);
            it = seen.erase(it);
        }
        std::sort(gone.begin(), gone.end());  // the file's order of removes does not follow the hash map's
        for (Uid gone_uid : gone) recorder.remove(gone_uid);
    }

    void put(const Object& o, bool insert) {
        if (o.shape.kind == ShapeKind::box)
            insert ? recorder.insert(o.uid, o.box) : recorder.move(o.uid, o.box);
        else
            insert ? recorder.insert(o.uid, o.shape) : recorder.move(o.uid, o.shape);
    }
};

namespace {

Vec3 vec(const btVector3& v) { return {float(v.x()), float(v.y()), float(v.z())}; }

/// The game's meta with where the recording came from, unless the game says it; meta that is not a
/// JSON object goes on unchanged, for Recorder to refuse.
std::string with_origin(const std::string& meta_json) {
    nlohmann::json meta = nlohmann::json::parse(meta_json, nullptr, false);
    if (!meta.is_object()) return meta_json;
    if (!meta.contains("generator")) meta["generator"] = "rcb::BulletRecorder";
    const int version = btGetVersion();  // 324 for 3.24
    if (!meta.contains("engine"))
        meta["engine"] = "Bullet " + std::to_string(version / 100) + (version % 100 < 10 ? ".0" : ".") +
                         std::to_string(version % 100);
    return meta.dump();
}

/// Refuses, before the recorder exists (whose destructor would write the file), a world whose
/// objects cannot all be recorded.
void check_objects(const btCollisionWorld& world, const std::string& path) {
    const btCollisionObjectArray& objects = world.getCollisionObjectArray();
    for (int i = 0; i < objects.size(); ++i)
        BulletRecorder::object_of(*objects[i], 0,
                                  "recorder " + path + ": frame 0: collision object " + std::to_string(i));
}

/// BulletRecorder::object_of's conversion, before its checks.
Object convert(const btCollisionObject& object, Uid uid, const std::string& where) {
    const btCollisionShape* shape = object.getCollisionShape();
    if (!shape) throw InputError(where + ": has no collision shape");
    const btTransform& t = object.getWorldTransform();
    const Vec3 centre = vec(t.getOrigin());
    switch (shape->getShapeType()) {
        case BOX_SHAPE_PROXYTYPE: {
            const btQuaternion q = t.getRotation();
            const auto* box = static_cast<const btBoxShape*>(shape);
            return shaped_object(uid, Shape::obb(centre, vec(box->getHalfExtentsWithMargin()),
                                                 {float(q.w()), float(q.x()), float(q.y()), float(q.z())}));
        }
        case SPHERE_SHAPE_PROXYTYPE:
            return shaped_object(uid,
                                 Shape::sphere(centre, float(static_cast<const btSphereShape*>(shape)->getRadius())));
        case CAPSULE_SHAPE_PROXYTYPE: {
            const auto* capsule = static_cast<const btCapsuleShape*>(shape);
            btVector3 axis(0, 0, 0);
            axis[capsule->getUpAxis()] = capsule->getHalfHeight();
            const btVector3 reach = t.getBasis() * axis;
            return shaped_object(uid, Shape::capsule(vec(t.getOrigin() - reach), vec(t.getOrigin() + reach),
                                                     float(capsule->getRadius())));
        }
        default: {
            btVector3 lo, hi;
            shape->getAabb(t, lo, hi);
            return Object{uid, Aabb{vec(lo), vec(hi)}};
        }
    }
}

}  // namespace

Object BulletRecorder::object_of(const btCollisionObject& object, Uid uid, const std::string& where) {
    const Object o = convert(object, uid, where);
    const bool box = o.shape.kind == ShapeKind::box;
    const std::string problem = box ? box_problem(o.box) : shape_problem(o.shape, kMaxCoordinate);
    if (problem.empty()) return o;
    const std::string shape = object.getCollisionShape()->getName();
    if (!box) throw InputError(where + " (" + shape + "): " + problem);
    throw InputError(where + " (" + shape + "): world AABB: " + problem +
                     " (rcbench records bounded objects: a ground plane can be a btBoxShape)");
}

BulletRecorder::BulletRecorder(const btCollisionWorld& world, std::string path, const std::string& meta_json)
    : state_((check_objects(world, path), std::make_unique<State>(world, std::move(path), with_origin(meta_json)))) {
    state_->record_objects();
    state_->recorder.end_frame();
}

BulletRecorder::~BulletRecorder() = default;  // ~Recorder writes the file if close() was not called

void BulletRecorder::step() {
    State& s = *state_;
    if (s.frame_used) s.recorder.end_frame();
    s.record_objects();
    s.frame_used = true;
}

void BulletRecorder::ray_test(const btVector3& from, const btVector3& to,
                              btCollisionWorld::RayResultCallback& callback) {
    using World = btCollisionWorld;
    const bool closest = dynamic_cast<World::ClosestRayResultCallback*>(&callback) != nullptr;
    ray_test(from, to, callback, closest ? QueryKind::closest : QueryKind::all);
}

void BulletRecorder::ray_test(const btVector3& from, const btVector3& to, btCollisionWorld::RayResultCallback& callback,
                              QueryKind kind) {
    State& s = *state_;
    s.recorder.ray({vec(from), vec(to)}, kind);  // first: a refused ray is not cast either
    s.frame_used = true;
    s.world->rayTest(from, to, callback);
}

void BulletRecorder::close() { state_->recorder.close(); }

std::optional<Uid> BulletRecorder::uid(const btCollisionObject* object) const {
    auto it = state_->seen.find(object);
    if (it == state_->seen.end()) return std::nullopt;
    return it->second.uid;
}

std::uint32_t BulletRecorder::frame() const { return state_->recorder.frame(); }
std::size_t BulletRecorder::live_count() const { return state_->recorder.live_count(); }
const Recorder& BulletRecorder::recorder() const { return state_->recorder; }

}  // namespace rcb

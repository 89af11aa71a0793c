#include "core/scene/scene.h"

#include <algorithm>
#include <cstdio>

#include "core/base/error.h"

namespace rcb {

double recording_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame) {
    constexpr double object_bytes = sizeof(Object), ray_bytes = sizeof(Segment);
    return objects * object_bytes + frames * (changes_per_frame * object_bytes + rays_per_frame * ray_bytes);
}

void check_object_count(double objects, const std::string& where) {
    if (!(objects <= double(kMaxSceneObjects)))
        throw InputError(where + ": " + std::to_string(std::uint64_t(std::min(objects, 1e19))) +
                         " objects, more than the limit of " + std::to_string(kMaxSceneObjects) + " per scene");
}

void check_scene_size(double objects, double frames, double rays_per_frame, double changes_per_frame,
                      const std::string& where) {
    check_object_count(objects, where);
    const double bytes = recording_bytes(objects, frames, rays_per_frame, changes_per_frame);
    if (!(bytes <= double(kMaxRecordingBytes))) {
        char text[160];
        std::snprintf(
            text, sizeof text,
            "the scene would take %.3g GB (%.0f objects, %.0f frames of %.0f rays), more than the limit of %.3g GB",
            bytes / 1e9, objects, frames, rays_per_frame, double(kMaxRecordingBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer frames, rays or objects");
    }
}

LiveSet::LiveSet(const std::vector<Object>& objects) {
    objects_.reserve(objects.size());
    index_.reserve(objects.size());
    for (const Object& o : objects) insert(o);
}

void LiveSet::insert(const Object& o) {
    index_.emplace(o.uid, static_cast<std::uint32_t>(objects_.size()));
    objects_.push_back(o);
}

void LiveSet::remove(Uid uid) {
    auto it = index_.find(uid);
    std::uint32_t slot = it->second;
    index_.erase(it);
    if (slot + 1 != objects_.size()) {
        objects_[slot] = objects_.back();
        index_[objects_[slot].uid] = slot;
    }
    objects_.pop_back();
}

void LiveSet::move(const Object& o) { objects_[index_.at(o.uid)] = o; }

void LiveSet::apply(const Frame& frame) {
    for (Uid uid : frame.removes) remove(uid);
    for (const Object& o : frame.inserts) insert(o);
    for (const Object& o : frame.moves) move(o);
}

Aabb bounds_of(const std::vector<Object>& objects) {
    Aabb b = Aabb::empty();
    for (const Object& o : objects) b = merge(b, o.box);
    return b;
}

}  // namespace rcb

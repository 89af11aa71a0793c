#include "core/scene/scene.h"

#include <algorithm>
#include <cstdio>

#include "core/base/error.h"
#include "core/scene/recording_stream.h"

namespace rcb {

double recording_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame) {
    constexpr double object_bytes = sizeof(Object), ray_bytes = sizeof(Segment);
    return objects * object_bytes + frames * (changes_per_frame * object_bytes + rays_per_frame * ray_bytes);
}

namespace {
/// The one bound both size checks share: at most kMaxSceneObjects objects.
void check_object_count(double objects, const std::string& where) {
    if (!(objects <= double(kMaxSceneObjects)))
        throw InputError(where + ": " + std::to_string(std::uint64_t(std::min(objects, 1e19))) +
                         " objects, more than the limit of " + std::to_string(kMaxSceneObjects) + " per scene");
}
}  // namespace

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

double streamed_file_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame) {
    constexpr double object_bytes = 4 + 1 + 10 * 4, ray_bytes = 6 * 4 + 1, frame_bytes = 16 + 5 * 4;
    return objects * object_bytes +
           frames * (frame_bytes + changes_per_frame * object_bytes + rays_per_frame * ray_bytes);
}

void check_streamed_scene_size(double objects, double frames, double rays_per_frame, double changes_per_frame,
                               const std::string& where) {
    check_object_count(objects, where);
    char text[200];
    const double frame = recording_bytes(objects, 1, rays_per_frame, changes_per_frame);
    if (!(frame <= double(kMaxRecordingBytes))) {
        std::snprintf(
            text, sizeof text,
            "one frame would take %.3g GB in memory (%.0f objects, %.0f rays), more than the limit of %.3g GB",
            frame / 1e9, objects, rays_per_frame, double(kMaxRecordingBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer rays or objects");
    }
    const double file = streamed_file_bytes(objects, frames, rays_per_frame, changes_per_frame);
    if (!(file <= double(kMaxStreamedFileBytes))) {
        std::snprintf(text, sizeof text,
                      "the recording could take %.3g GB on disk (%.0f objects, %.0f frames of %.0f rays), more than "
                      "the limit of %.3g GB",
                      file / 1e9, objects, frames, rays_per_frame, double(kMaxStreamedFileBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer frames, rays or objects");
    }
    // Streaming lifts the bound for moving objects, not for rays: a recording's rays stay within
    // the in-memory bound, as before, so that an absurd --rays is refused instead of generated.
    const double rays = streamed_file_bytes(0, frames, rays_per_frame, 0);
    if (!(rays <= double(kMaxRecordingBytes))) {
        std::snprintf(text, sizeof text,
                      "the recording's rays could take %.3g GB (%.0f frames of %.0f rays), more than the limit of "
                      "%.3g GB",
                      rays / 1e9, frames, rays_per_frame, double(kMaxRecordingBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer rays or frames");
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

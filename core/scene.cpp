#include "core/scene.h"

namespace rcb {

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

void LiveSet::move(Uid uid, const Aabb& box) { objects_[index_.at(uid)].box = box; }

void LiveSet::apply(const Frame& frame) {
    for (Uid uid : frame.removes) remove(uid);
    for (const Object& o : frame.inserts) insert(o);
    for (const Object& o : frame.moves) move(o.uid, o.box);
}

Aabb bounds_of(const std::vector<Object>& objects) {
    Aabb b = Aabb::empty();
    for (const Object& o : objects) b = merge(b, o.box);
    return b;
}

}  // namespace rcb

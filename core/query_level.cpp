#include "core/query_level.h"

#include <algorithm>

namespace rcb {

ParamSpec query_param_spec() {
    ParamSpec p;
    p.name = "query";
    p.kind = ParamKind::choice;
    p.choices = {"candidates", "boxes", "shapes"};
    p.default_value = "boxes";
    p.doc =
        "query level: candidates (the traversal's output, no final box test), boxes (exact box test), shapes "
        "(narrow phase on the exact shapes)";
    p.tunable = false;
    p.recorded_when_default = false;
    return p;
}

QueryLevel query_level_of(const nlohmann::json& params) {
    if (!params.is_object() || !params.contains("query")) return QueryLevel::boxes;
    const std::string q = params.at("query").get<std::string>();
    return q == "candidates" ? QueryLevel::candidates : (q == "shapes" ? QueryLevel::shapes : QueryLevel::boxes);
}

nlohmann::json own_params(const nlohmann::json& params) {
    if (!params.is_object()) return params;
    nlohmann::json own = params;
    own.erase("query");
    return own;
}

Contract contract_of(const nlohmann::json& params) {
    const bool tight_leaves = params.is_object() && params.contains("leaf_bv") && params.at("leaf_bv") != "aabb";
    switch (query_level_of(params)) {
        case QueryLevel::candidates:
            return {Truth::boxes, std::nullopt};
        case QueryLevel::shapes:
            return {Truth::shapes, Truth::shapes};
        case QueryLevel::boxes:
            break;
    }
    return {tight_leaves ? Truth::shapes : Truth::boxes, Truth::boxes};
}

std::unique_ptr<Structure> at_query_level(std::unique_ptr<Structure> broad, QueryLevel level) {
    if (level == QueryLevel::candidates) broad->set_candidates_only(true);
    if (level == QueryLevel::shapes) return std::make_unique<NarrowPhase>(std::move(broad));
    return broad;
}

NarrowPhase::NarrowPhase(std::unique_ptr<Structure> broad) : broad_(std::move(broad)) {}

void NarrowPhase::set(const Object& o) {
    // Dense while uids stay below four times the object count (with a floor for small scenes).
    const std::size_t dense_limit = 4 * (broad_->size() + 1024);
    if (o.uid >= dense_.size() && o.uid < dense_limit) {
        dense_.resize(std::size_t(o.uid) + 1);
        for (auto it = sparse_.begin(); it != sparse_.end();)  // uids the table now covers move into it
            if (it->first < dense_.size()) {
                dense_[it->first] = it->second;
                it = sparse_.erase(it);
            } else {
                ++it;
            }
    }
    Entry& e = o.uid < dense_.size() ? dense_[o.uid] : sparse_[o.uid];
    if (e.live) shaped_ -= e.shape.kind != ShapeKind::box;
    live_ += !e.live;
    shaped_ += o.shape.kind != ShapeKind::box;
    e = {o.box, o.shape, true};
}

void NarrowPhase::erase(Uid uid) {
    const Entry& e = entry(uid);
    shaped_ -= e.shape.kind != ShapeKind::box;
    --live_;
    if (uid < dense_.size())
        dense_[uid] = Entry{};
    else
        sparse_.erase(uid);
}

void NarrowPhase::build(std::span<const Object> objects) {
    broad_->build(objects);
    dense_.clear();
    sparse_.clear();
    live_ = shaped_ = 0;
    for (const Object& o : objects) set(o);
}

void NarrowPhase::insert(const Object& object) {
    broad_->insert(object);
    set(object);
}

void NarrowPhase::remove(Uid uid) {
    broad_->remove(uid);
    erase(uid);
}

void NarrowPhase::move(const Object& object) {
    broad_->move(object);
    set(object);
}

template <class Tally>
void NarrowPhase::filter(std::span<const Segment> rays, HitLists& hits, Tally&& tally) const {
    if (shaped_ == 0) return;  // boxes only: every box hit is a hit
    // In place: a ray's kept hits move down over the dropped ones.
    std::uint32_t write = 0, begin = 0;
    for (std::size_t r = 0; r < rays.size(); ++r) {
        const std::uint32_t end = hits.offsets[r + 1];
        for (std::uint32_t i = begin; i < end; ++i) {
            const Uid uid = hits.uids[i];
            const Shape& shape = entry(uid).shape;
            if (shape.kind != ShapeKind::box) {
                const bool hit = segment_hits_shape(rays[r], shape);
                tally(hit);
                if (!hit) continue;
            }
            hits.uids[write++] = uid;
        }
        begin = end;
        hits.offsets[r + 1] = write;
    }
    hits.uids.resize(write);
}

void NarrowPhase::cast(std::span<const Segment> rays, HitLists& out) {
    broad_->cast(rays, out);
    filter(rays, out, [](bool) {});
}

void NarrowPhase::cast_counted(std::span<const Segment> rays, HitLists& out, Counters& counters) {
    broad_->cast_counted(rays, out, counters);
    filter(rays, out, [&](bool hit) {
        ++counters.n_ro;
        counters.n_ro_hits += hit;
    });
}

std::optional<Hit> NarrowPhase::cast_closest(const Segment& segment) {
    // Every box hit, then the nearest entry into a shape: a box's entry says nothing of its shape's.
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    const SegmentSlabs slabs(segment);
    std::optional<Hit> best;
    for (Uid uid : scratch_.of(0)) {
        const Entry& e = entry(uid);
        float t = 0, t_far;
        if (e.shape.kind != ShapeKind::box ? !segment_hits_shape(segment, e.shape, &t) : !slabs.clip(e.box, t, t_far))
            continue;
        if (!best || t < best->t || (t == best->t && uid < best->uid)) best = Hit{uid, t};
    }
    return best;
}

bool NarrowPhase::cast_any(const Segment& segment) {
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    for (Uid uid : scratch_.of(0)) {
        const Shape& shape = entry(uid).shape;
        if (shape.kind == ShapeKind::box || segment_hits_shape(segment, shape)) return true;
    }
    return false;
}

std::size_t NarrowPhase::memory_bytes() const {
    return broad_->memory_bytes() + dense_.capacity() * sizeof(Entry) +
           sparse_.size() * (sizeof(Entry) + sizeof(Uid) + 2 * sizeof(void*));
}

void NarrowPhase::validate() const {
    broad_->validate();
    std::size_t live = sparse_.size(), shaped = 0;
    for (const Entry& e : dense_) live += e.live;
    for (const Entry& e : dense_) shaped += e.live && e.shape.kind != ShapeKind::box;
    for (const auto& [uid, e] : sparse_) shaped += e.shape.kind != ShapeKind::box;
    if (live != live_ || shaped != shaped_) broken_invariant("narrow phase", "object counts differ from its table");
    if (live != broad_->size()) broken_invariant("narrow phase", "holds another object count than its structure");
}

}  // namespace rcb

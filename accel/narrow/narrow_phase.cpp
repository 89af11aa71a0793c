#include "accel/narrow/narrow_phase.h"

#include "core/base/error.h"

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
    own.erase("leaf_bv");
    return own;
}

Contract contract_of(const nlohmann::json& params) {
    const bool tight_leaves = leaf_bv_of(params) != LeafBv::aabb;
    const bool robust = !(params.is_object() && params.contains("robust") && params.at("robust") == false);
    Contract c;
    switch (query_level_of(params)) {
        case QueryLevel::candidates:
            c = {Truth::boxes, std::nullopt};
            break;
        case QueryLevel::shapes:
            c = {Truth::shapes, Truth::shapes};
            break;
        case QueryLevel::boxes:
            c = {tight_leaves ? Truth::shapes : Truth::boxes, Truth::boxes};
            break;
    }
    if (!robust) c.lower.reset();
    return c;
}

std::unique_ptr<Structure> at_query_level(std::unique_ptr<Structure> broad, QueryLevel level, LeafBv bv,
                                          const std::string& path) {
    if (level == QueryLevel::candidates && bv != LeafBv::aabb)
        throw InputError(join_path(path, "leaf_bv") +
                         ": a tighter volume needs query boxes or shapes (candidates test no volume)");
    if (level == QueryLevel::candidates) broad->set_candidates_only(true);
    if (level == QueryLevel::shapes || bv != LeafBv::aabb)
        return std::make_unique<NarrowPhase>(std::move(broad), level == QueryLevel::shapes, bv);
    return broad;
}

NarrowPhase::NarrowPhase(std::unique_ptr<Structure> broad, bool shapes, LeafBv bv)
    : broad_(std::move(broad)), shapes_(shapes), bv_(bv) {}

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
    std::uint32_t volume = e.volume;
    if (bv_ != LeafBv::aabb) {
        LeafVolume v = leaf_volume(o, bv_);
        if (v.bv == LeafBv::aabb && volume != kNoVolume) {
            free_volumes_.push_back(volume);
            volume = kNoVolume;
        } else if (v.bv != LeafBv::aabb) {
            if (volume == kNoVolume) {
                if (free_volumes_.empty()) {
                    volume = std::uint32_t(volumes_.size());
                    volumes_.emplace_back();
                } else {
                    volume = free_volumes_.back();
                    free_volumes_.pop_back();
                }
            }
            volumes_[volume] = v;
        }
    }
    e = {o.box, o.shape, true, volume};
}

void NarrowPhase::erase(Uid uid) {
    const Entry& e = entry(uid);
    shaped_ -= e.shape.kind != ShapeKind::box;
    --live_;
    if (e.volume != kNoVolume) free_volumes_.push_back(e.volume);
    if (uid < dense_.size())
        dense_[uid] = Entry{};
    else
        sparse_.erase(uid);
}

void NarrowPhase::build(std::span<const Object> objects) {
    broad_->build(objects);
    dense_.clear();
    sparse_.clear();
    volumes_.clear();
    free_volumes_.clear();
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
bool NarrowPhase::survives(const Segment& s, const Entry& e, float* t, Tally&& tally) const {
    if (e.shape.kind == ShapeKind::box) return true;  // its box hit is the hit
    if (e.volume != kNoVolume && !segment_hits_volume(s, e.box, volumes_[e.volume])) return false;
    if (!shapes_) return true;
    const bool hit = segment_hits_shape(s, e.shape, t);
    tally(hit);
    return hit;
}

template <class Tally>
void NarrowPhase::filter(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& hits,
                         Tally&& tally) const {
    // In place: a ray's kept hits move down over the dropped ones; closest and any keep one.
    std::uint32_t write = 0, begin = 0;
    for (std::size_t r = 0; r < rays.size(); ++r) {
        const std::uint32_t end = hits.offsets[r + 1];
        const QueryKind kind = kinds.empty() ? QueryKind::all : kinds[r];
        if (kind == QueryKind::closest) {
            // The nearest entry into a shape: a box's entry says nothing of its shape's.
            const SegmentSlabs slabs(rays[r]);
            ClosestHit closest;
            for (std::uint32_t i = begin; i < end; ++i) {
                const Entry& e = entry(hits.uids[i]);
                float t = 0, t_far;
                if (slabs.clip(e.box, t, t_far) && survives(rays[r], e, &t, tally)) closest(hits.uids[i], t);
            }
            if (closest.found) hits.uids[write++] = closest.uid;
        } else {
            for (std::uint32_t i = begin; i < end; ++i) {
                const Uid uid = hits.uids[i];
                if (!survives(rays[r], entry(uid), nullptr, tally)) continue;
                hits.uids[write++] = uid;
                if (kind == QueryKind::any) break;
            }
        }
        begin = end;
        hits.offsets[r + 1] = write;
    }
    hits.uids.resize(write);
}

void NarrowPhase::cast(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out) {
    // Boxes only: every box hit is a hit, and the structure answers each kind itself.
    if (shaped_ == 0) return broad_->cast(rays, kinds, out);
    broad_->cast(rays, {}, out);
    filter(rays, kinds, out, [](bool) {});
}

void NarrowPhase::cast_counted(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out,
                               Counters& counters) {
    if (shaped_ == 0) return broad_->cast_counted(rays, kinds, out, counters);
    broad_->cast_counted(rays, {}, out, counters);
    filter(rays, kinds, out, [&](bool hit) {
        ++counters.n_ro;
        counters.n_ro_hits += hit;
    });
}

std::optional<Hit> NarrowPhase::cast_closest(const Segment& segment) {
    // Every box hit, then the nearest entry into a shape: a box's entry says nothing of its shape's.
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    const SegmentSlabs slabs(segment);
    ClosestHit closest;
    for (Uid uid : scratch_.of(0)) {
        const Entry& e = entry(uid);
        float t = 0, t_far;
        if (slabs.clip(e.box, t, t_far) && survives(segment, e, &t, [](bool) {})) closest(uid, t);
    }
    if (!closest.found) return std::nullopt;
    return Hit{closest.uid, closest.t_limit};
}

bool NarrowPhase::cast_any(const Segment& segment) {
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    for (Uid uid : scratch_.of(0))
        if (survives(segment, entry(uid), nullptr, [](bool) {})) return true;
    return false;
}

std::size_t NarrowPhase::memory_bytes() const {
    return broad_->memory_bytes() + dense_.capacity() * sizeof(Entry) +
           sparse_.size() * (sizeof(Entry) + sizeof(Uid) + 2 * sizeof(void*)) +
           volumes_.capacity() * sizeof(LeafVolume) + free_volumes_.capacity() * sizeof(std::uint32_t);
}

void NarrowPhase::check() const {
    broad_->check();
    std::size_t live = sparse_.size(), shaped = 0;
    for (const Entry& e : dense_) live += e.live;
    for (const Entry& e : dense_) shaped += e.live && e.shape.kind != ShapeKind::box;
    for (const auto& [uid, e] : sparse_) shaped += e.shape.kind != ShapeKind::box;
    if (live != live_ || shaped != shaped_) broken_invariant("narrow phase", "object counts differ from its table");
    if (live != broad_->size()) broken_invariant("narrow phase", "holds another object count than its structure");
}

}  // namespace rcb

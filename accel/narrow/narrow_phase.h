#pragma once
/// Query levels: how far a structure's answer goes, one parameter (`query`) that the registry gives
/// every structure and peer.
///
///     candidates  what the traversal reaches with no final test of the object's box (a grid
///                 cell's objects, a BVH leaf whose stored box is hit), each once per ray: the
///                 broad phase's output as an engine's narrow phase receives it
///     boxes       the exact test of the objects' boxes (the default, and every result before
///                 query levels existed)
///     shapes      the narrow phase: each box hit tested against the object's exact shape
///                 (shape.h), boxes passing through
///
/// The thesis' model separates the costs of the levels (eq. 5.2–5.3): candidates whose box is
/// missed are traversal-caused false positives (N_TFP), box hits whose shape is missed are
/// bounding-volume false positives (N_BFP), and the narrow phase costs C_RO per shape test.
///
/// A box hit is tested against a tighter leaf volume first where `leaf_bv` names one (leaf_volume.h).

#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/truth/ground_truth.h"
#include "accel/interface/params.h"
#include "accel/interface/structure.h"
#include "accel/narrow/leaf_volume.h"

namespace rcb {

enum class QueryLevel { candidates, boxes, shapes };

/// The `query` parameter's spec. It is recorded only when it is not `boxes`, so a result of the
/// box level keeps the parameters (and the configuration identity) it had before.
ParamSpec query_param_spec();
/// The level named by `params["query"]` (boxes when absent); `params` is already validated.
QueryLevel query_level_of(const nlohmann::json& params);

/// `params` without the keys the registry handles for every structure.
nlohmann::json own_params(const nlohmann::json& params);

/// What a configuration's hit sets promise (ground_truth.h), from its complete parameters: the
/// query level, and a leaf bounding volume tighter than the box (`leaf_bv`) where there is one.
Contract contract_of(const nlohmann::json& params);

/// `broad` answering at `level` with `bv`: the candidate level switched on, or the volume test and
/// the narrow phase put after it. InputError (naming `path`) for a tighter volume at the
/// candidate level, which tests no box.
std::unique_ptr<Structure> at_query_level(std::unique_ptr<Structure> broad, QueryLevel level, LeafBv bv,
                                          const std::string& path);

/// The narrow phase after any structure: the structure's hits (its boxes, or a tighter leaf
/// volume) filtered by the exact shape test, as engines run their narrow phase on the broad
/// phase's pairs. Counts n_ro (shape tests) and n_ro_hits in the counting pass.
class NarrowPhase final : public Structure {
public:
    /// `shapes`: test the shapes (the shapes level); `bv`: the tighter volume tested first.
    NarrowPhase(std::unique_ptr<Structure> broad, bool shapes, LeafBv bv);

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override { broad_->commit(); }
    std::uint64_t writes() const override { return broad_->writes(); }
    using Structure::cast;
    using Structure::cast_counted;
    void cast(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out) override;
    void cast_counted(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out,
                      Counters& counters) override;
    std::optional<Hit> cast_closest(const Segment& segment) override;
    bool cast_any(const Segment& segment) override;
    void set_candidates_only(bool on) override { broad_->set_candidates_only(on); }
    std::size_t size() const override { return broad_->size(); }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override { return broad_->stats(); }
    void check() const override;

private:
    struct Entry {
        Aabb box = Aabb::empty();
        Shape shape;
        bool live = false;
        std::uint32_t volume = kNoVolume;  ///< index into volumes_
    };
    static constexpr std::uint32_t kNoVolume = ~std::uint32_t(0);
    /// The live object `uid` (precondition: live).
    const Entry& entry(Uid uid) const { return uid < dense_.size() ? dense_[uid] : sparse_.at(uid); }
    void set(const Object& o);
    void erase(Uid uid);
    /// Whether a box hit of `e` passes its tighter volume and, at the shapes level, its shape
    /// (`t`: the shape's entry, when given); `tally(hit)` after each shape test.
    template <class Tally>
    bool survives(const Segment& s, const Entry& e, float* t, Tally&& tally) const;
    /// The broad phase's all hits of each ray cut to its kind's answer (query kinds: structure.h).
    template <class Tally>
    void filter(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& hits, Tally&& tally) const;

    std::unique_ptr<Structure> broad_;
    bool shapes_;
    LeafBv bv_;
    std::vector<LeafVolume> volumes_;  // slots of the live objects' volumes, free ones listed
    std::vector<std::uint32_t> free_volumes_;
    // uid → entry: a table indexed by uid while uids are dense (every generator's and importer's
    // are), so the narrow phase pays an array read per box hit; a hash map for the other uids.
    std::vector<Entry> dense_;
    std::unordered_map<Uid, Entry> sparse_;
    std::size_t live_ = 0, shaped_ = 0;  // live objects, and those with a shape
    HitLists scratch_;
};

}  // namespace rcb

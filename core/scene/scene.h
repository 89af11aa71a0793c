#pragma once
/// A scene recording: the thesis' data-generator output (§5.2.1). Frame 0's objects, then per frame
/// the changes (inserts, removes, moves) and the rays cast in that frame. The simulator replays it
/// against a structure; the file format is in recording_io.h.

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/base/geometry.h"
#include "core/scene/shape.h"

namespace rcb {

using Uid = std::uint32_t;

/// An object: its box, and the exact shape inside it (shape.h; by default the box itself). A
/// shaped object's box is shape_bounds(shape): make one with shaped_object.
struct Object {
    Uid uid = 0;
    Aabb box;
    Shape shape;

    constexpr Object() = default;
    /// A box object (the default shape), or with its shape: `shape`'s bounds must be `box`.
    constexpr Object(Uid u, const Aabb& b, const Shape& s = {}) : uid(u), box(b), shape(s) {}
    friend bool operator==(const Object&, const Object&) = default;
};

inline Object shaped_object(Uid uid, const Shape& shape) { return {uid, shape_bounds(shape), shape}; }

/// What a ray asks (docs/accuracy.md, "Query kinds"): every object its segment meets (`all`, the
/// thesis' workload: penetration, sensors), the nearest one (`closest`: shots, ground probes,
/// cameras) or whether it meets any (`any`: line of sight, visibility).
enum class QueryKind : std::uint8_t { all = 0, closest = 1, any = 2 };
inline constexpr int kQueryKinds = 3;
inline constexpr const char* kQueryKindNames[kQueryKinds] = {"all", "closest", "any"};
inline const char* query_kind_name(QueryKind kind) { return kQueryKindNames[int(kind)]; }

/// One frame's changes and rays. Changes apply in the order removes, inserts, moves; a uid appears
/// at most once among a frame's changes.
struct Frame {
    std::vector<Object> inserts;
    std::vector<Uid> removes;
    std::vector<Object> moves;  // uid and its new box (and shape)
    std::vector<Segment> rays;
    /// The query kind of each ray, or empty when every ray is `all` (then the file keeps its
    /// older format version, recording_io.h).
    std::vector<QueryKind> kinds;
    friend bool operator==(const Frame&, const Frame&) = default;

    QueryKind kind(std::size_t ray) const { return kinds.empty() ? QueryKind::all : kinds[ray]; }

    std::size_t change_count() const { return inserts.size() + removes.size() + moves.size(); }
};

struct Recording {
    /// Free-form JSON text describing where the scene came from (generator and its settings, seed,
    /// source file). Stored in the file so a result can always be traced back to its inputs.
    std::string meta = "{}";
    std::vector<Object> initial;
    std::vector<Frame> frames;
    friend bool operator==(const Recording&, const Recording&) = default;
};

/// The live object set while a recording is replayed: uid → box, kept dense (swap-remove) so a
/// whole-set pass is a plain loop. Used by the simulator's ground truth, the generators and the
/// validating reader.
class LiveSet {
public:
    LiveSet() = default;
    explicit LiveSet(const std::vector<Object>& objects);

    bool contains(Uid uid) const { return index_.count(uid) != 0; }
    std::size_t size() const { return objects_.size(); }
    const std::vector<Object>& objects() const { return objects_; }
    const Aabb& box(Uid uid) const { return objects_[index_.at(uid)].box; }
    const Object& object(Uid uid) const { return objects_[index_.at(uid)]; }

    /// Preconditions (checked by callers that face user input): insert of a new uid, remove and
    /// move of a live one.
    void insert(const Object& o);
    void remove(Uid uid);
    void move(const Object& o);  ///< new box and shape
    void apply(const Frame& frame);

private:
    std::vector<Object> objects_;
    std::unordered_map<Uid, std::uint32_t> index_;
};

/// Bounds on a scene, checked before anything is allocated, so a typo in a count is a clear error
/// instead of minutes of work ending in std::bad_alloc. 2^26 objects are 64 times the largest
/// scene of the experiments (10^6); 4 GiB of recording is a sixth of the machines rcbench targets.
inline constexpr std::uint64_t kMaxSceneObjects = std::uint64_t(1) << 26;
inline constexpr std::uint64_t kMaxRecordingBytes = std::uint64_t(4) << 30;

/// InputError "<where>: N objects, more than the limit of ..." beyond kMaxSceneObjects (NaN
/// included): the bound both size checks (below, and recording_stream.h's) share.
void check_object_count(double objects, const std::string& where);
/// Bytes a recording of these counts takes in memory (about its file size).
double recording_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame);
/// InputError "<where>: ..." naming the limit when a scene of these counts exceeds one of the bounds
/// above (NaN counts included).
void check_scene_size(double objects, double frames, double rays_per_frame, double changes_per_frame,
                      const std::string& where);

/// Bounds of a set of objects (the empty box for none).
Aabb bounds_of(const std::vector<Object>& objects);

}  // namespace rcb

#pragma once
/// A scene recording: the thesis' data-generator output (§5.2.1). Frame 0's objects, then per frame
/// the changes (inserts, removes, moves) and the rays cast in that frame. The simulator replays it
/// against a structure; the file format is in recording_io.h.

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/geometry.h"

namespace rcb {

using Uid = std::uint32_t;

struct Object {
    Uid uid = 0;
    Aabb box;
    friend bool operator==(const Object&, const Object&) = default;
};

/// One frame's changes and rays. Changes apply in the order removes, inserts, moves; a uid appears
/// at most once among a frame's changes.
struct Frame {
    std::vector<Object> inserts;
    std::vector<Uid> removes;
    std::vector<Object> moves;  // uid and its new box
    std::vector<Segment> rays;
    friend bool operator==(const Frame&, const Frame&) = default;

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

    /// Preconditions (checked by callers that face user input): insert of a new uid, remove and
    /// move of a live one.
    void insert(const Object& o);
    void remove(Uid uid);
    void move(Uid uid, const Aabb& box);
    void apply(const Frame& frame);

private:
    std::vector<Object> objects_;
    std::unordered_map<Uid, std::uint32_t> index_;
};

/// Bounds of a set of objects (the empty box for none).
Aabb bounds_of(const std::vector<Object>& objects);

}  // namespace rcb

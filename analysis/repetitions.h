#pragma once
/// What stands for a cell's repetitions in one run. Every repetition of a cell replays the same
/// recording on a freshly built structure, so frame k asks the same work of each and counts the same
/// nodes, hits and changes; only the times differ. Another process on the machine only ever adds
/// time, so the fastest measurement of a frame is the least disturbed one (Chen & Revels 2016,
/// "Robust benchmarking in noisy environments": the minimum, not the median, is the estimator that
/// repeats under load).

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "runner/results_reader.h"

namespace rcb {

/// `median`: each repetition's median over its frames, then the median over the repetitions (the
/// figure the cell table stores). `fastest`: each frame's fastest time over the repetitions, ray
/// cast and update each on its own, then the median over the frames. `fastest_cast`: each frame's
/// fastest ray cast and its median update over the repetitions, then the median over the frames.
/// The update bends the minimum's premise: how much of its memory the shared last-level cache still
/// holds when it starts depends on the other core and the host, so that state subtracts time as
/// well as adding it, and the fastest repetition is the luckiest state, not the least disturbed
/// (docs/model.md as of commit f3b2207, "How well two runs agree").
enum class OverRepetitions { median, fastest, fastest_cast };

/// "median", "fastest" or "fastest-cast".
const char* repetitions_name(OverRepetitions how);
/// What `how` takes from the repetitions, in a phrase ("each frame's fastest time over its repetitions").
const char* repetitions_phrase(OverRepetitions how);
/// Every name `repetitions_name` gives, in the enum's order.
std::vector<std::string> repetitions_names();
/// The value of a name `repetitions_name` gives; nothing for any other text.
std::optional<OverRepetitions> parse_repetitions(const std::string& name);

/// A run's figure of one cell: ray-cast and update time per frame in ns, over `repetitions`.
struct CellFigure {
    double raycast_ns = 0, update_ns = 0;
    std::size_t repetitions = 0;
};
/// Per (scene id, config id): the figure of every cell of run `run` and its sibling shards.
std::map<std::pair<std::int64_t, std::int64_t>, CellFigure> cell_figures(Database& db, std::int64_t run,
                                                                         OverRepetitions how);

/// (scene id, config id, frame) of a measured frame.
using FrameKey = std::tuple<std::int64_t, std::int64_t, std::int64_t>;
/// Per measured (non-warm-up) frame of run `run` and its sibling shards: the median of its update
/// times over the cell's repetitions.
std::map<FrameKey, double> median_update_per_frame(Database& db, std::int64_t run);

}  // namespace rcb

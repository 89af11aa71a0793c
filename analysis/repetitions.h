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
#include <utility>

#include "runner/sqlite.h"

namespace rcb {

/// `median`: each repetition's median over its frames, then the median over the repetitions (the
/// figure the cell table stores). `fastest`: each frame's fastest time over the repetitions, ray
/// cast and update each on its own, then the median over the frames.
enum class OverRepetitions { median, fastest };

/// "median" or "fastest".
const char* repetitions_name(OverRepetitions how);
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

}  // namespace rcb

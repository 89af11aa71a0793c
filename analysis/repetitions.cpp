#include "analysis/repetitions.h"

#include <stdexcept>
#include <vector>

#include "sim/simulator.h"
#include "runner/results_reader.h"

namespace rcb {

namespace {

/// Every reading: its name (the option's value) and what it takes, in a phrase.
struct Reading {
    OverRepetitions how;
    const char* name;
    const char* phrase;
};
constexpr Reading kReadings[] = {
    {OverRepetitions::median, "median", "the median over its repetitions of each repetition's median over frames"},
    {OverRepetitions::fastest, "fastest", "the median over frames of each frame's fastest time over its repetitions"},
    {OverRepetitions::fastest_cast, "fastest-cast",
     "the median over frames of each frame's fastest ray cast and median update over its repetitions"},
};

const Reading& reading(OverRepetitions how) {
    for (const Reading& r : kReadings)
        if (r.how == how) return r;
    throw std::logic_error("a reading of repetitions without a name");
}

}  // namespace

const char* repetitions_name(OverRepetitions how) { return reading(how).name; }

const char* repetitions_phrase(OverRepetitions how) { return reading(how).phrase; }

std::vector<std::string> repetitions_names() {
    std::vector<std::string> out;
    for (const Reading& r : kReadings) out.emplace_back(r.name);
    return out;
}

std::optional<OverRepetitions> parse_repetitions(const std::string& name) {
    for (const Reading& r : kReadings)
        if (name == r.name) return r.how;
    return std::nullopt;
}

std::map<FrameKey, double> median_update_per_frame(Database& db, std::int64_t run) {
    std::map<FrameKey, std::vector<double>> times;
    // Warm-up frames are left out, as in the cell's own median (sim/simulator.h).
    for (const FrameTimeRow& r : read_frame_times(db, run))
        times[{r.scene_id, r.config_id, r.frame}].push_back(r.update_ns);
    std::map<FrameKey, double> out;
    for (const auto& [key, v] : times) out.emplace_hint(out.end(), key, spread_of(v).median);
    return out;
}

std::map<std::pair<std::int64_t, std::int64_t>, CellFigure> cell_figures(Database& db, std::int64_t run,
                                                                         OverRepetitions how) {
    using Key = std::pair<std::int64_t, std::int64_t>;
    std::map<Key, std::pair<std::vector<double>, std::vector<double>>> medians, per_frame;
    for (const CellMediansRow& r : read_cell_medians(db, run)) {
        auto& v = medians[{r.scene_id, r.config_id}];
        v.first.push_back(r.raycast_ns_median);
        v.second.push_back(r.update_ns_median);
    }
    if (how != OverRepetitions::median) {
        const std::map<FrameKey, double> update_median =
            how == OverRepetitions::fastest_cast ? median_update_per_frame(db, run) : std::map<FrameKey, double>{};
        for (const FrameTimeRow& r : read_fastest_frame_times(db, run)) {
            const FrameKey frame{r.scene_id, r.config_id, r.frame};
            auto& v = per_frame[{r.scene_id, r.config_id}];
            v.first.push_back(r.raycast_ns);
            v.second.push_back(how == OverRepetitions::fastest ? r.update_ns : update_median.at(frame));
        }
    }
    // A cell without measured frames (every frame a warm-up) keeps its stored medians.
    std::map<Key, CellFigure> out;
    for (const auto& [key, m] : medians) {
        const auto f = per_frame.find(key);
        const auto& v = f == per_frame.end() ? m : f->second;
        out[key] = {spread_of(v.first).median, spread_of(v.second).median, m.first.size()};
    }
    return out;
}

}  // namespace rcb

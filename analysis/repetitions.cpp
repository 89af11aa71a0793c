#include "analysis/repetitions.h"

#include <stdexcept>
#include <vector>

#include "core/sim/simulator.h"
#include "runner/store.h"

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
    // Warm-up frames are left out, as in the cell's own median (core/sim/simulator.h).
    Statement s = db.prepare(std::string("SELECT cell.scene_id, cell.config_id, frame.frame, frame.update_ns FROM "
                                         "frame JOIN cell ON cell.id = frame.cell_id WHERE frame.warmup = 0 AND "
                                         "cell.run_id IN ") +
                             kRunGroupSql);
    s.bind_all(run, run);
    while (s.step()) times[{s.int64(0), s.int64(1), s.int64(2)}].push_back(s.real(3));
    std::map<FrameKey, double> out;
    for (const auto& [key, v] : times) out.emplace_hint(out.end(), key, spread_of(v).median);
    return out;
}

std::map<std::pair<std::int64_t, std::int64_t>, CellFigure> cell_figures(Database& db, std::int64_t run,
                                                                         OverRepetitions how) {
    using Key = std::pair<std::int64_t, std::int64_t>;
    std::map<Key, std::pair<std::vector<double>, std::vector<double>>> medians, per_frame;
    {
        Statement s = db.prepare(std::string("SELECT scene_id, config_id, raycast_ns_median, update_ns_median FROM "
                                             "cell WHERE run_id IN ") +
                                 kRunGroupSql);
        s.bind_all(run, run);
        while (s.step()) {
            auto& v = medians[{s.int64(0), s.int64(1)}];
            v.first.push_back(s.real(2));
            v.second.push_back(s.real(3));
        }
    }
    if (how != OverRepetitions::median) {
        const std::map<FrameKey, double> update_median =
            how == OverRepetitions::fastest_cast ? median_update_per_frame(db, run) : std::map<FrameKey, double>{};
        Statement s = db.prepare(std::string("SELECT cell.scene_id, cell.config_id, frame.frame, "
                                             "min(frame.raycast_ns), min(frame.update_ns) FROM frame JOIN cell ON "
                                             "cell.id = frame.cell_id WHERE frame.warmup = 0 AND cell.run_id IN ") +
                                 kRunGroupSql + " GROUP BY cell.scene_id, cell.config_id, frame.frame");
        s.bind_all(run, run);
        while (s.step()) {
            const FrameKey frame{s.int64(0), s.int64(1), s.int64(2)};
            auto& v = per_frame[{s.int64(0), s.int64(1)}];
            v.first.push_back(s.real(3));
            v.second.push_back(how == OverRepetitions::fastest ? s.real(4) : update_median.at(frame));
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

#include "analysis/repetitions.h"

#include <vector>

#include "core/sim/simulator.h"
#include "runner/store.h"

namespace rcb {

const char* repetitions_name(OverRepetitions how) { return how == OverRepetitions::fastest ? "fastest" : "median"; }

std::optional<OverRepetitions> parse_repetitions(const std::string& name) {
    for (OverRepetitions how : {OverRepetitions::median, OverRepetitions::fastest})
        if (name == repetitions_name(how)) return how;
    return std::nullopt;
}

std::map<std::pair<std::int64_t, std::int64_t>, CellFigure> cell_figures(Database& db, std::int64_t run,
                                                                         OverRepetitions how) {
    using Key = std::pair<std::int64_t, std::int64_t>;
    std::map<Key, std::pair<std::vector<double>, std::vector<double>>> medians, fastest;
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
    if (how == OverRepetitions::fastest) {
        // Warm-up frames are left out, as in the cell's own median (core/sim/simulator.h).
        Statement s = db.prepare(std::string("SELECT cell.scene_id, cell.config_id, min(frame.raycast_ns), "
                                             "min(frame.update_ns) FROM frame JOIN cell ON cell.id = frame.cell_id "
                                             "WHERE frame.warmup = 0 AND cell.run_id IN ") +
                                 kRunGroupSql + " GROUP BY cell.scene_id, cell.config_id, frame.frame");
        s.bind_all(run, run);
        while (s.step()) {
            auto& v = fastest[{s.int64(0), s.int64(1)}];
            v.first.push_back(s.real(2));
            v.second.push_back(s.real(3));
        }
    }
    // A cell without measured frames (every frame a warm-up) keeps its stored medians.
    std::map<Key, CellFigure> out;
    for (const auto& [key, m] : medians) {
        const auto f = fastest.find(key);
        const auto& v = f == fastest.end() ? m : f->second;
        out[key] = {spread_of(v.first).median, spread_of(v.second).median, m.first.size()};
    }
    return out;
}

}  // namespace rcb

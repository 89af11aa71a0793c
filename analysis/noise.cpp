#include "analysis/noise.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>

#include "core/base/number_text.h"
#include "core/sim/simulator.h"
#include "runner/run_experiment.h"
#include "runner/store.h"

namespace rcb {

namespace {

/// Every value a time that can be compared: a damaged database can hold anything.
bool all_finite_positive(const std::vector<double>& values) {
    return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v) && v > 0; });
}

}  // namespace

std::vector<StructureNoise> repeatability(const std::vector<RepeatSample>& samples) {
    // structure → cell → repetitions
    std::map<std::string, std::map<std::string, std::vector<const RepeatSample*>>> by;
    for (const RepeatSample& s : samples) by[s.structure][s.cell].push_back(&s);
    std::vector<StructureNoise> out;
    for (const auto& [structure, cells] : by) {
        StructureNoise n;
        n.structure = structure;
        std::vector<double> cast, update, frame;
        for (const auto& [cell, reps] : cells) {
            for (const RepeatSample* r : reps) n.slow += r->slow;
            if (reps.size() < 2) continue;
            ++n.cells;
            n.repetitions += reps.size();
            std::vector<double> c, u, f;
            for (const RepeatSample* r : reps)
                if (r->repetition < 2)
                    c.push_back(r->raycast_ns), u.push_back(r->update_ns), f.push_back(r->raycast_ns + r->update_ns);
            if (c.size() < 2) continue;
            // Only finite spreads count.
            auto add = [](std::vector<double>& to, const std::vector<double>& values) {
                if (all_finite_positive(values)) to.push_back(relative_range(values));
            };
            add(cast, c);
            add(update, u);
            add(frame, f);
        }
        n.raycast = quantile(cast, 0.5);
        n.raycast_p90 = quantile(cast, 0.9);
        n.update = quantile(update, 0.5);
        n.update_p90 = quantile(update, 0.9);
        n.frame = quantile(frame, 0.5);
        n.frame_p90 = quantile(frame, 0.9);
        out.push_back(n);
    }
    return out;
}

const StructureNoise* NoiseFloor::find(const std::string& structure) const {
    for (const StructureNoise& s : structures)
        if (s.structure == structure) return &s;
    return nullptr;
}

NoiseFloor noise_floor(Database& db, std::int64_t run) {
    // Cells of runs made before the machine state have no cell_state row: NULL.
    Statement s =
        db.prepare(std::string("SELECT config.structure, cell.scene_id, cell.config_id, cell.raycast_ns_median, "
                               "cell.update_ns_median, cell_state.slow, cell_state.load_1m, cell_state.calibration_ns, "
                               "cell.repetition "
                               "FROM cell JOIN config ON config.id = cell.config_id "
                               "LEFT JOIN cell_state ON cell_state.cell_id = cell.id WHERE cell.run_id IN ") +
                   kRunGroupSql);
    s.bind_all(run, run);
    NoiseFloor out;
    std::vector<RepeatSample> samples;
    std::vector<double> load, calibration;
    while (s.step()) {
        RepeatSample r;
        r.structure = s.text(0);
        r.cell = std::to_string(s.int64(1)) + ":" + std::to_string(s.int64(2));
        r.raycast_ns = s.real(3);
        r.update_ns = s.real(4);
        r.repetition = s.int64(8);
        ++out.cells;
        if (!s.is_null(5)) {
            r.slow = s.int64(5) != 0;
            out.slow += r.slow;
            ++out.with_state;
            if (s.real(6) >= 0 && std::isfinite(s.real(6))) load.push_back(s.real(6));
            if (std::isfinite(s.real(7))) calibration.push_back(s.real(7));
        }
        samples.push_back(std::move(r));
    }
    out.structures = repeatability(samples);
    if (!load.empty()) out.load_median = spread_of(load).median;
    if (!calibration.empty()) out.calibration_median_ns = spread_of(calibration).median;
    return out;
}

namespace {

/// Per (structure, scene hash, params): the run's figure of the cell (`how`); `slow` counts each
/// key's repetitions flagged slow.
std::map<std::string, std::pair<double, double>> run_medians(Database& db, std::int64_t run, OverRepetitions how,
                                                             std::map<std::string, std::string>& structure_of,
                                                             std::map<std::string, std::size_t>& slow) {
    Statement s = db.prepare(std::string("SELECT cell.scene_id, cell.config_id, config.structure, scene.hash, "
                                         "config.params, coalesce(cell_state.slow, 0) FROM cell "
                                         "JOIN config ON config.id = cell.config_id JOIN scene ON scene.id = "
                                         "cell.scene_id LEFT JOIN cell_state ON cell_state.cell_id = cell.id "
                                         "WHERE cell.run_id IN ") +
                             kRunGroupSql);
    s.bind_all(run, run);
    const auto figures = cell_figures(db, run, how);
    std::map<std::string, std::pair<double, double>> out;
    while (s.step()) {
        const std::string key = s.text(2) + '\n' + s.text(3) + '\n' + s.text(4);
        structure_of[key] = s.text(2);
        slow[key] += s.int64(5) != 0;
        const CellFigure& f = figures.at({s.int64(0), s.int64(1)});
        out[key] = {f.raycast_ns, f.update_ns};
    }
    return out;
}

/// Each run's figure of a cell as one "repetition" of it: repeatability's spread of two is then the
/// relative range of the runs. `pooled`: every cell under the one structure "all".
std::vector<RepeatSample> between_samples(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                          OverRepetitions how, bool pooled) {
    std::map<std::string, std::string> structure_of;
    std::map<std::string, std::size_t> slow;
    const auto in_a = run_medians(a, run_a, how, structure_of, slow);
    const auto in_b = run_medians(b, run_b, how, structure_of, slow);
    std::vector<RepeatSample> samples;
    for (const auto& [key, ma] : in_a) {
        const auto mb = in_b.find(key);
        if (mb == in_b.end()) continue;
        const std::string structure = pooled ? "all" : structure_of[key];
        samples.push_back({structure, key, ma.first, ma.second, slow[key] > 0, 0});
        samples.push_back({structure, key, mb->second.first, mb->second.second, false, 1});
    }
    return samples;
}

}  // namespace

std::vector<StructureNoise> between_runs(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                         OverRepetitions how) {
    return repeatability(between_samples(a, run_a, b, run_b, how, false));
}

StructureNoise between_runs_pooled(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                   OverRepetitions how) {
    const std::vector<StructureNoise> all = repeatability(between_samples(a, run_a, b, run_b, how, true));
    if (!all.empty()) return all.front();
    StructureNoise none;
    none.structure = "all";
    return none;
}

std::vector<UpdateBand> between_runs_by_update(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                               OverRepetitions how) {
    const double edges[] = {0, 10e3, 30e3, 100e3, INFINITY};
    constexpr std::size_t kBands = std::size(edges) - 1;
    std::vector<double> range[kBands], share[kBands];
    // between_samples gives each cell both runs hold as two samples in a row, run a's first.
    const std::vector<RepeatSample> samples = between_samples(a, run_a, b, run_b, how, true);
    for (std::size_t i = 0; i + 1 < samples.size(); i += 2) {
        const RepeatSample &x = samples[i], &y = samples[i + 1];
        if (!all_finite_positive({x.update_ns, y.update_ns, x.raycast_ns, y.raycast_ns})) continue;
        const double size = std::sqrt(x.update_ns * y.update_ns);
        const std::size_t band = std::size_t(std::upper_bound(std::begin(edges), std::end(edges), size) - edges) - 1;
        range[band].push_back(relative_range({x.update_ns, y.update_ns}));
        share[band].push_back((x.update_ns + y.update_ns) / (x.update_ns + y.update_ns + x.raycast_ns + y.raycast_ns));
    }
    std::vector<UpdateBand> out;
    for (std::size_t k = 0; k < kBands; ++k)
        out.push_back({edges[k], edges[k + 1], range[k].size(), quantile(range[k], 0.5), quantile(range[k], 0.9),
                       quantile(share[k], 0.5)});
    return out;
}

std::vector<SlowCell> slow_cells(Database& db, std::int64_t run) {
    std::vector<SlowCell> out;
    // The ratio is against the median of the cell's own run (each shard has its own machine).
    std::map<std::int64_t, double> medians;
    {
        Statement s = db.prepare(
            "SELECT cell.run_id, cell_state.calibration_ns FROM cell JOIN cell_state ON cell_state.cell_id = cell.id "
            "WHERE cell.run_id IN " +
            std::string(kRunGroupSql));
        s.bind_all(run, run);
        std::map<std::int64_t, std::vector<double>> times;
        while (s.step()) times[s.int64(0)].push_back(s.real(1));
        for (auto& [r, t] : times) medians[r] = spread_of(t).median;
    }
    Statement s =
        db.prepare("SELECT " + std::string(kSceneLabelSql) +
                   ", config.structure, config.params, cell.repetition, cell_state.load_1m, "
                   "cell_state.calibration_ns, cell.run_id FROM cell JOIN cell_state ON cell_state.cell_id = cell.id "
                   "JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id "
                   "WHERE cell_state.slow = 1 AND cell.run_id IN " +
                   std::string(kRunGroupSql) + " ORDER BY cell.id");
    s.bind_all(run, run);
    while (s.step()) {
        const double median = medians[s.int64(6)];
        out.push_back({s.text(0), s.text(1), s.text(2), s.int64(3), s.real(4), median > 0 ? s.real(5) / median : NAN});
    }
    return out;
}

std::string noise_text(double p50, double p90) {
    return std::isfinite(p50) ? noise_text(p50) + " / " + noise_text(p90) : "-";
}

std::string noise_text(double deviation) { return std::isfinite(deviation) ? fixed(100 * deviation, 1) + "%" : "-"; }

}  // namespace rcb

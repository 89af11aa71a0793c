#pragma once
/// The HTML report of a run: the thesis' tables (6.1 build, 6.2 ray cast and update, 6.3 cost
/// breakdown, 6.4 DBVH incremental vs full SAH) and charts drawn by gnuplot (update against ray
/// cast, time per frame against precision and recall with each scene's Pareto front named,
/// predicted against measured, per-frame series, SAH cost over time, memory against time, build
/// time against object count), each scene's motion (objects changed per frame) and, for a run with
/// query kinds, the time per query of each kind measured and predicted (analysis/query_kinds.h),
/// and on physics scenes, per phase and query kind, per frame of every configuration with the best
/// own against each peer's best configuration, named (as on every other scene with a peer).
/// One self-contained file: open it from disk, no network, no scripts.
/// What each section shows is loaded and computed in analysis/report_data.h; report.cpp only
/// renders it (HTML, CSS, gnuplot charts).

#include <cstdint>
#include <string>

#include "runner/results_reader.h"

namespace rcb {

struct ReportSummary {
    std::int64_t run = 0;
    std::size_t charts = 0;
    std::size_t tables = 0;
};

/// Writes the report of `run` to `path` (atomically: a temporary file renamed into place).
ReportSummary write_report(Database& db, std::int64_t run, const std::string& path);

}  // namespace rcb

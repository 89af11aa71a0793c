#pragma once
/// The validation summaries as terminal tables: `fit` prints nested leave-one-scene-out with them,
/// `validate` every split.

#include <string>
#include <vector>

#include "analysis/noise.h"
#include "analysis/validation.h"
#include "cli/table.h"

namespace rcb {

/// "12.3%", "-" for NaN.
std::string percent(double v);

/// One row per structure: cells, scenes, median and p90 of the frame and ray-cast errors (with
/// their bootstrap intervals where computed), unpredictable cells, the ray-cast forms the splits
/// chose. `indent` prefixes the first column.
TextTable validation_table(const ValidationGroup& group, const std::string& indent);

/// The held-out error beside the spread between two runs of the same cells (analysis/noise.h
/// between_runs), one row per structure of `group`: frame error median and p90, the two runs'
/// frame spread median and p90 over the cells both hold, and each error over its spread (a model
/// cannot be told apart from a rerun where that is at most 1).
TextTable spread_table(const ValidationGroup& group, const std::vector<StructureNoise>& spread,
                       const std::string& indent);

/// Groups of ray-cast errors only, one per query kind ("kind:closest", …): one row per structure
/// and kind with cells, scenes, median and p90 of the ray-cast error with their intervals, and
/// unpredictable cells.
TextTable kind_validation_table(const std::vector<ValidationGroup>& groups, const std::string& indent);

}  // namespace rcb

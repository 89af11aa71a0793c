#pragma once
/// Combining results databases (shards of one experiment, runs from several machines) into one.

#include <cstddef>

#include "runner/sqlite.h"
#include "runner/store.h"

namespace rcb {

struct MergeCount {
    std::size_t runs = 0;   ///< runs new to the output
    std::size_t cells = 0;  ///< cells new to the output, in new runs or in runs it had unfinished
    /// The input's fits, validations and derived categories of its runs, none of them copied: they
    /// describe the input's cells alone (a shard's fit, a part of its run), so the merged run is
    /// fitted again.
    std::size_t analyses = 0;
};

/// Copies into `out` every run of `in` (matched by run uuid) and every cell of it that `out` does
/// not have yet, remapping ids, in the order the input stored them (the order they were measured,
/// which whatever reads cells by id keeps); a run `out` holds unfinished gains the cells finished
/// since and its finish time. So merging a shard, resuming the shard and merging it again completes the run.
/// Each merged run's cell_interval rows are then computed again from its cells in `out`; its fits,
/// validations and derived categories are left behind and counted.
/// One transaction: all of `in` or nothing. `in` is at the latest schema, as open_read_only gives
/// any older file.
MergeCount merge_into(ResultStore& out, Database& in);

}  // namespace rcb

// The engine's own rcbench: rcbench's whole command line (rcbench::cli, cli/cli.h) with SweepList
// registered beside rcbench's structures, so that run, fit, tune, advise, report, compare and
// history know "sweep" as they know "dbvh". Its runs are stored under its own name (run.binary).
//
//     engine_rcbench run quick_sweep.json --db sweep.db && engine_rcbench fit sweep.db
#include <cli/cli.h>
#include <accel/registry.h>

#include "sweep_list.h"

int main(int argc, char** argv) {
    rcb::register_structure<engine::SweepList>("sweep", engine::kSweepListSummary);
    return rcb::cli::main(argc, argv);
}

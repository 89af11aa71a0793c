// A run of an experiment killed by SIGKILL at a known point, for the runner's resume tests:
//
//   rcb_killed_run EXPERIMENT DB CELLS [K/N]
//
// runs EXPERIMENT (shard K/N, default 1/1) into DB through run_experiment, as `rcbench run` does,
// and kills itself with SIGKILL as the cell after the first CELLS starts: CELLS cells are stored
// and the run is left unfinished, whatever the machine's speed. (A test that kills `rcbench run`
// from outside once it sees CELLS cells races the run: on a loaded machine the run can finish
// first.) Exit 0 when the plan has no more than CELLS cells to run; 2 on bad arguments.
#include <signal.h>

#include <cstdlib>
#include <iostream>
#include <string>

#include "runner/experiment.h"
#include "runner/run_experiment.h"

int main(int argc, char** argv) {
    if (argc != 4 && argc != 5) {
        std::cerr << "usage: rcb_killed_run EXPERIMENT DB CELLS [K/N]\n";
        return 2;
    }
    const std::string experiment = argv[1];
    const std::size_t cells = std::strtoull(argv[3], nullptr, 10);
    rcb::RunOptions options;
    options.db = argv[2];
    if (argc == 5) {
        const std::string shard = argv[4];
        const std::size_t slash = shard.find('/');
        if (slash == std::string::npos) {
            std::cerr << "rcb_killed_run: shard: expected K/N, got " << shard << '\n';
            return 2;
        }
        options.shard_k = std::strtoull(shard.substr(0, slash).c_str(), nullptr, 10);
        options.shard_n = std::strtoull(shard.substr(slash + 1).c_str(), nullptr, 10);
    }
    const rcb::Experiment e = rcb::load_experiment(experiment);
    rcb::run_experiment(e, experiment, options, [cells](std::size_t ran, std::size_t, const std::string&) {
        if (ran == cells) ::raise(SIGKILL);  // `ran` cells are stored; the next has not begun
    });
    return 0;
}

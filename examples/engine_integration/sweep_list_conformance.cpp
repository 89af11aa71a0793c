// rcbench's conformance suite (rcbench::testing) on the engine's structure: exactness against the
// ground truth for all, closest and any hit on rcbench's hard scenes, at random parameters and on
// a fuzz scene, check() after every frame, and the refusal of bad parameters. GoogleTest's
// main (GTest::gtest_main) runs it; a failure names the scene, the ray and the missed or extra uid.
#include <testing/conformance.h>

#include "sweep_list.h"

using engine::SweepList;

RCB_CONFORMANCE_TESTS(SweepList, "sweep")

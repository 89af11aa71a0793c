# Headers that moved, installed at their old paths as forwarding headers that include the new
# place, so an engine that includes an old path still builds against this release. They go with the
# next one: include the new paths. The moves: core/ split into stages (base, scene, truth, accel,
# sim); brute force from accel/ into accel/scan/; the repetition interval into the one statistics
# header; then accel and sim out of core/ as stages of their own (core/accel/ -> accel/, its loose
# files into accel/interface/, accel/model/ and accel/narrow/, query_level.h now narrow_phase.h
# with the leaf volumes in leaf_volume.h; core/sim/ -> sim/).
set(RCB_MOVED_HEADERS
  core/error.h=core/base/error.h
  core/geometry.h=core/base/geometry.h
  core/random.h=core/base/random.h
  core/number_text.h=core/base/number_text.h
  core/json_input.h=core/base/json_input.h
  core/output_file.h=core/base/output_file.h
  core/scene.h=core/scene/scene.h
  core/shape.h=core/scene/shape.h
  core/recording_io.h=core/scene/recording_io.h
  core/recorder.h=core/scene/recorder.h
  core/generators.h=core/scene/generate/generators.h
  core/csv.h=core/scene/import/csv.h
  core/importers/bsp.h=core/scene/import/bsp.h
  core/importers/model.h=core/scene/import/model.h
  core/importers/nesting.h=core/scene/import/nesting.h
  core/importers/scene_import.h=core/scene/import/scene_import.h
  core/ground_truth.h=core/truth/ground_truth.h
  core/hit_lists.h=core/truth/hit_lists.h
  core/structure.h=accel/interface/structure.h
  core/params.h=accel/interface/params.h
  core/registry.h=accel/registry.h
  core/counters.h=accel/model/counters.h
  core/outcome_predictor.h=accel/model/outcome_predictor.h
  core/cast_arena.h=accel/interface/cast_arena.h
  core/query_level.h=accel/narrow/narrow_phase.h
  core/structures/brute_force.h=accel/scan/brute_force.h
  core/accel/brute_force.h=accel/scan/brute_force.h
  core/structures/common/box_block.h=accel/common/box_block.h
  core/structures/common/box_scan.h=accel/common/box_scan.h
  core/structures/common/outlier_trim.h=accel/common/outlier_trim.h
  core/structures/common/query_scratch.h=accel/common/query_scratch.h
  core/structures/common/slot_boxes.h=accel/common/slot_boxes.h
  core/structures/common/bvh_traversal.h=accel/bvh/bvh_traversal.h
  core/structures/common/grid.h=accel/grid/grid.h
  core/structures/uniform_grid.h=accel/grid/uniform_grid.h
  core/structures/hash_grid.h=accel/grid/hash_grid.h
  core/structures/dynamic_bvh.h=accel/bvh/dynamic_bvh.h
  core/structures/linear_bvh.h=accel/bvh/linear_bvh.h
  core/structures/wide_bvh.h=accel/bvh/wide_bvh.h
  core/peers/bullet_dbvt.h=accel/peers/bullet_dbvt.h
  core/peers/embree_boxes.h=accel/peers/embree_boxes.h
  core/simulator.h=sim/simulator.h
  core/scene_features.h=sim/scene_features.h
  core/base/repetition_interval.h=core/base/statistics.h
  core/accel/bvh/binned_sah.h=accel/bvh/binned_sah.h
  core/accel/bvh/bvh_traversal.h=accel/bvh/bvh_traversal.h
  core/accel/bvh/dynamic_bvh.h=accel/bvh/dynamic_bvh.h
  core/accel/bvh/linear_bvh.h=accel/bvh/linear_bvh.h
  core/accel/bvh/wide_bvh.h=accel/bvh/wide_bvh.h
  core/accel/bvh/wide_bvh_build.h=accel/bvh/wide_bvh_build.h
  core/accel/bvh/wide_bvh_index.h=accel/bvh/wide_bvh_index.h
  core/accel/bvh/wide_bvh_rebuild.h=accel/bvh/wide_bvh_rebuild.h
  core/accel/cache_model.h=accel/model/cache_model.h
  core/accel/cast_arena.h=accel/interface/cast_arena.h
  core/accel/common/box_block.h=accel/common/box_block.h
  core/accel/common/box_scan.h=accel/common/box_scan.h
  core/accel/common/exact_collector.h=accel/common/exact_collector.h
  core/accel/common/outlier_trim.h=accel/common/outlier_trim.h
  core/accel/common/query_scratch.h=accel/common/query_scratch.h
  core/accel/common/slot_boxes.h=accel/common/slot_boxes.h
  core/accel/counter_fields.h=accel/model/counter_fields.h
  core/accel/counters.h=accel/model/counters.h
  core/accel/grid/grid.h=accel/grid/grid.h
  core/accel/grid/hash_grid.h=accel/grid/hash_grid.h
  core/accel/grid/uniform_grid.h=accel/grid/uniform_grid.h
  core/accel/hit_policy.h=accel/interface/hit_policy.h
  core/accel/outcome_predictor.h=accel/model/outcome_predictor.h
  core/accel/params.h=accel/interface/params.h
  core/accel/peers/bullet_dbvt.h=accel/peers/bullet_dbvt.h
  core/accel/peers/embree_boxes.h=accel/peers/embree_boxes.h
  core/accel/peers/ode_spaces.h=accel/peers/ode_spaces.h
  core/accel/query_level.h=accel/narrow/narrow_phase.h
  core/accel/registry.h=accel/registry.h
  core/accel/scan/brute_force.h=accel/scan/brute_force.h
  core/accel/structure.h=accel/interface/structure.h
  core/sim/cache_sweep.h=sim/cache_sweep.h
  core/sim/scene_features.h=sim/scene_features.h
  core/sim/simulator.h=sim/simulator.h
)
foreach(move IN LISTS RCB_MOVED_HEADERS)
  string(REPLACE "=" ";" move "${move}")
  list(GET move 0 old)
  list(GET move 1 new)
  get_filename_component(dir "${old}" DIRECTORY)
  set(forward "${PROJECT_BINARY_DIR}/forwarding/${old}")
  file(WRITE "${forward}.in" "// Moved to ${new}; this forwarding header goes with the next release.\n#pragma once\n#include \"${new}\"\n")
  configure_file("${forward}.in" "${forward}" COPYONLY)
  install(FILES "${forward}" DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/rcbench/${dir})
endforeach()

#pragma once
/// Scene generators (the thesis' data generator, §5.2.1, rebuilt without Unity): a static object
/// set, per-frame dynamics, and per-frame rays. Deterministic: the same settings give the same
/// recording, byte for byte. Scene, dynamics and rays draw from separate streams derived from the
/// seed, so e.g. changing the number of rays does not change the dynamics.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/random.h"
#include "core/scene/scene.h"

namespace rcb {

/// How the objects change from frame to frame (thesis §5.2.1: 1% per frame by default).
struct DynamicsSettings {
    double change_fraction = 0.01;  ///< objects changed per frame, as a fraction of the live count
    double insert_share = 0.1;      ///< of the changes, the share that are inserts
    double remove_share = 0.1;      ///< … removes (the rest are moves)
    double move_scale = 0.1;        ///< a move shifts each axis by up to this × the object's longest edge
};

/// Ray modes: `center` (thesis §6.1: from the scene centre in uniform directions, long enough to
/// leave the scene), `dense` (§6.4: from the centre towards the densest region), and game uses
/// (§3.2): `los` (line of sight between two objects' centres), `ground` (short downward rays from
/// object tops), `shots` (short segments from objects in random directions), and `faces`
/// (for stability tests: axis-parallel segments across the bounds lying in box face planes, along box edges,
/// and in the planes of dyadic lattices over the bounds, where cells meet), and `inside` (from a
/// random point inside a random object's box in a uniform direction, long enough to leave the
/// scene: rays that start among a crowd). The query presets' modes start on an agent (a random live
/// object) just outside its bounding sphere, so an agent does not answer its own query (but for a
/// sight line between agents whose spheres overlap, which shrinks to a point between them): `fire` (a
/// shot: uniform direction, a quarter of the scene's diagonal long), `sight` (from one agent towards
/// another, ending just outside the other's bounding sphere) and `sensor` (uniform direction, three
/// times the agent's longest edge long).
struct RayMode {
    std::string mode;
    double weight = 1;
    /// Set by a query preset: every ray of this mode asks this kind (query_preset_mix). Unset: the
    /// kind comes from RaySettings::query_mix, as before presets.
    std::optional<QueryKind> kind = std::nullopt;
};

/// A query kind (scene.h) and its weight in a frame's rays.
struct QueryShare {
    QueryKind kind = QueryKind::all;
    double weight = 1;
};

struct RaySettings {
    std::uint32_t per_frame = 1000;
    std::vector<RayMode> mix{{"center", 1.0}};
    /// Empty (or only `all`): every ray asks for all hits, the thesis' workload. Must be empty
    /// when a mode carries its own kind (a query preset).
    std::vector<QueryShare> query_mix;
    std::string queries;  ///< the query preset `mix` came from (query_preset_mix), if any
};

/// Game query presets: each a mix of (ray mode, kind) that mirrors how a game asks, its name
/// recorded in the recording's meta (docs/recording-format.md, "Query presets"):
///   shots       `fire` rays, closest hit: what a shot from an agent hits first
///   visibility  `sight` rays, any hit: is the line between two agents blocked
///   sensors     `sensor` rays, all hits: what lies within a few object sizes of an agent
///   game        our blend of the three, 50% shots, 30% visibility, 20% sensors; half the rays are
///               closest-hit shots as in Bullet's benchmark demo (500 closest rays per frame of
///               1000 rays here)
std::vector<std::string> query_preset_names();
/// The preset's modes with their kinds and weights; InputError naming the known presets otherwise.
std::vector<RayMode> query_preset_mix(std::string_view name);
/// `rays` with the preset `name` applied: its mix, its name recorded, no query mix.
RaySettings with_query_preset(RaySettings rays, std::string_view name);
/// InputError when a mode carries a kind and a query mix is given too (the kinds would conflict).
void check_ray_settings(const RaySettings& rays);
/// What the recording's meta says of its rays: per_frame, the modes (each with its kind when a
/// preset set one), the query mix when some ray is not `all`, the preset when one was used.
/// Recordings without kinds or a preset get the bytes they had before presets.
nlohmann::json rays_json(const RaySettings& rays);

/// Which generated objects get an exact shape inside their box (shape.h), as shares of frame 0's
/// objects; the rest stay boxes. A rotated object is an oriented box with the generated box's half
/// extents and a uniformly random rotation, so its bounds (its new box) grow; a sphere is inscribed
/// in the generated box, a capsule lies along the box's longest axis, inscribed too. Shaped
/// objects give the ray–object test of the thesis' model (eq. 5.3, C_RO) and bv-caused false
/// positives (eq. 5.2, N_BFP) something to measure. All 0 (the default) leaves a scene's bytes as
/// they were.
struct ShapeSettings {
    double rotated_share = 0;
    double sphere_share = 0;
    double capsule_share = 0;
    bool any() const { return rotated_share > 0 || sphere_share > 0 || capsule_share > 0; }
};

// The pragmas keep the deprecated `kind` below from warning in SceneSettings' own implicit
// constructors (GCC warns there); code that names `kind` is still warned.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
struct SceneSettings {
    std::string generator = "irregular";  ///< one of scene_generators()
    std::uint32_t objects = 14021;
    std::uint64_t seed = 1;
    std::uint32_t frames = 10;
    /// Physics generators (physics.h): seconds simulated per frame; 0 takes the generator's
    /// default (physics_time_step: 1/60 for rcbench's generators, Broadmark's 1/30 for its three).
    double time_step = 0;
    /// Broadmark's generators (brownian, freefall, gravity; physics.h): its object set, "cubes",
    /// "spheres" or "assorted" (empty: cubes), and the share of the arena's volume the objects'
    /// nominal unit volumes fill (0: Broadmark's 0.1).
    std::string shape_set;
    double fill = 0;
    DynamicsSettings dynamics;
    ShapeSettings shapes;
    RaySettings rays;
    std::string preset;  ///< the preset it came from, if any (recorded in the meta)
    /// `generator`'s old name, kept for one release so that code written before the rename still
    /// builds: when set, it names the generator in place of `generator` for every function here
    /// that takes SceneSettings (with_generator). rcbench never sets it, so it reads empty. It goes
    /// with the next release.
    [[deprecated("use SceneSettings::generator")]] std::string kind = {};
};
#pragma GCC diagnostic pop

/// `settings` with its deprecated `kind`, when set, moved into `generator`; the functions that take
/// SceneSettings read their settings through it.
SceneSettings with_generator(const SceneSettings& settings);

/// The thesis' scenes (§6.1) by name: uni-s, uni-m, uni-l, irreg-s, irreg-m, irreg-l (99, 5 104
/// and 14 021 objects), plus irreg-xl (1 000 000 objects). The peer-comparison scenes, harder than
/// the thesis': jittered-m, jittered-l, clusters-m, clusters-l (5 104 and 14 021 objects) and
/// clusters-xl (1 000 000).
/// Failure-mode presets "<generator>-s" (1 000 objects) and "<generator>-m" (10 000) for every
/// generator of failure_mode_generators().
SceneSettings preset_settings(std::string_view name);
std::vector<std::string> preset_names();

/// Every generator generate_scene knows: "uniform" and "irregular" (thesis §6.1), "jittered" and
/// "clusters" (the peer-comparison scenes, generators.cpp says how they are drawn), the failure
/// modes, and the physics generators (physics.h).
std::vector<std::string> scene_generators();
/// Scenes built to break a structure's assumptions: "stadium" (one huge box around a
/// tiny dense cluster), "identical" (stacks of identical boxes), "same-centroid" (stacks with one
/// centroid and sizes over four orders of magnitude), "flat" (zero-thickness boxes in one plane),
/// "slivers" (long thin and zero-volume boxes), "outlier" (irregular plus one box 10^6 world sizes
/// away), "nested" (every object shares one centroid: cubes nested around the origin, sizes over
/// four orders of magnitude).
std::vector<std::string> failure_mode_generators();
/// scene_generators' and failure_mode_generators' old names, kept for one release; they go with
/// the next.
[[deprecated("use scene_generators")]] inline std::vector<std::string> scene_kinds() { return scene_generators(); }
[[deprecated("use failure_mode_generators")]] inline std::vector<std::string> failure_mode_kinds() {
    return failure_mode_generators();
}

/// "center", "center:0.7,los:0.3": modes with weights. Throws InputError on unknown modes.
std::vector<RayMode> parse_ray_mix(const std::string& text);
std::vector<std::string> ray_mode_names();
/// "closest:0.6,any:0.3,all:0.1": query kinds with weights. Throws InputError on unknown kinds.
std::vector<QueryShare> parse_query_mix(const std::string& text);
/// Whether every ray of the mix asks for all hits (an empty mix too).
bool asks_all_only(const std::vector<QueryShare>& mix);
/// The query kinds of one frame's `rays` rays: the mix's exact shares (largest remainder),
/// shuffled from the seed's own stream (the rays and the dynamics do not change when a mix is
/// added). Empty when every ray is `all`.
std::vector<QueryKind> generate_kinds(std::size_t rays, const std::vector<QueryShare>& mix, std::uint64_t seed,
                                      std::uint32_t frame);
/// The query kinds of one frame's `rays` rays (generate_rays' for the same settings): by each
/// mode's own kind when a preset set them (the rays come in the mix's order, so the kind of ray i
/// is its mode's), else generate_kinds from the query mix. Empty when every ray is `all`.
std::vector<QueryKind> ray_kinds(std::size_t rays, const RaySettings& settings, std::uint64_t seed,
                                 std::uint32_t frame);
/// [{"kind": "closest", "weight": 0.6}, …], as the recording's meta stores it.
nlohmann::json query_mix_json(const std::vector<QueryShare>& mix);

/// Frame 0's objects of a generated scene, shaped as `settings.shapes` asks (a physics
/// generator's bodies at rest before its first step).
std::vector<Object> generate_objects(const SceneSettings& settings);

/// Gives exactly round(share × n) of the objects each shape (chosen at random, the rotations too,
/// from the `seed`'s own stream: the boxes' draws are unchanged). Keeps uids; each shaped object's
/// box becomes its shape's bounds.
std::vector<Object> apply_shapes(std::vector<Object> objects, const ShapeSettings& shapes, std::uint64_t seed);

/// InputError naming the setting when a share is outside [0, 1] or not a number, or the shares add
/// up to more than 1.
void check_shapes(const ShapeSettings& shapes);

/// A full recording: generated objects, then `settings.frames` frames of dynamics and rays.
Recording generate_scene(const SceneSettings& settings);
/// InputError naming the setting when a share or scale is outside its range or not a number.
void check_dynamics(const DynamicsSettings& dynamics);

/// Gives any static object set (an import) the same dynamics and rays. A move translates an
/// object's shape with its box (kind and rotation kept); an insert copies a live object's shape. `meta` is stored as
/// given, with the dynamics, ray settings, frames and seed added.
Recording add_dynamics(std::vector<Object> initial, const DynamicsSettings& dynamics, const RaySettings& rays,
                       std::uint32_t frames, std::uint64_t seed, nlohmann::json meta);

/// Replaces every frame's rays of `r` by generate_rays on the objects live after its changes, and
/// their kinds by ray_kinds (for recordings that come without rays, such as Broadmark files).
void add_rays(Recording& r, const RaySettings& rays, std::uint64_t seed);

/// The rays of one frame for the given live objects (used by add_dynamics; exposed for tests).
std::vector<Segment> generate_rays(const std::vector<Object>& live, const RaySettings& rays, std::uint64_t seed,
                                   std::uint32_t frame);

nlohmann::json to_json(const SceneSettings& settings);

/// A uniformly random unit quaternion (w, x, y, z) (Shoemake 1992, "Uniform random rotations").
std::array<float, 4> random_rotation(Random& rng);

}  // namespace rcb

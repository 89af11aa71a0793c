// A Bullet game records its own workload and asks rcbench which structure to ship for it:
//   (a) a stock-shapes scene as Bullet's BasicDemo builds it (examples/BasicDemo/BasicExample.cpp:
//       a static ground box, a 5×5×5 lattice of bodies dropped onto it; here boxes and spheres
//       alternate), stepped 600 times at 60 Hz, casting per step four closest-hit shots from a
//       player and one all-hits probe down through the pile, recorded by rcb::BulletRecorder
//       (three lines: construct it with the world, step() after each step, cast through it);
//   (b) rcbench's `advise` on the recording, through rcbench's command line as a library
//       (rcb::cli::main): every structure measured on the game's own workload, one recommended.
// Exit codes are advise's (0, or 2 on bad input such as an unwritable output path).
//
//     bullet_game [out.rcbscene] [advise options…]   (default: <temp dir>/bullet_game.rcbscene)

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <btBulletDynamicsCommon.h>

#include <cli/cli.h>
#include <core/base/error.h>
#include <core/scene/bullet/bullet_recorder.h>

namespace {

/// The game: Bullet's world and the bodies it owns.
struct Game {
    btDefaultCollisionConfiguration config;
    btCollisionDispatcher dispatcher{&config};
    btDbvtBroadphase broadphase;
    btSequentialImpulseConstraintSolver solver;
    btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &config};
    btBoxShape ground_shape{btVector3(50, 50, 50)};
    btBoxShape box_shape{btVector3(0.5f, 0.5f, 0.5f)};
    btSphereShape sphere_shape{0.5f};
    std::vector<std::unique_ptr<btDefaultMotionState>> states;
    std::vector<std::unique_ptr<btRigidBody>> bodies;

    Game() {
        world.setGravity(btVector3(0, -10, 0));
        add(ground_shape, btVector3(0, -50, 0), 0);
        for (int i = 0; i < 5; ++i)
            for (int j = 0; j < 5; ++j)
                for (int k = 0; k < 5; ++k) {
                    btCollisionShape& shape =
                        (i + j + k) % 2 ? static_cast<btCollisionShape&>(sphere_shape) : box_shape;
                    add(shape, btVector3(1.1f * float(i - 2), 2.0f + 1.1f * float(k), 1.1f * float(j - 2)), 1);
                }
    }
    ~Game() {
        for (auto& body : bodies) world.removeRigidBody(body.get());
    }
    void add(btCollisionShape& shape, const btVector3& at, float mass) {
        btVector3 inertia(0, 0, 0);
        if (mass > 0) shape.calculateLocalInertia(mass, inertia);
        states.push_back(std::make_unique<btDefaultMotionState>(btTransform(btQuaternion::getIdentity(), at)));
        bodies.push_back(std::make_unique<btRigidBody>(mass, states.back().get(), &shape, inertia));
        world.addRigidBody(bodies.back().get());
    }
};

void record_game(const std::string& path) {
    Game game;
    rcb::BulletRecorder rec(game.world, path, R"({"game": "bullet_recording example"})");  // 1: frame 0
    int hits = 0;
    for (int step = 0; step < 600; ++step) {
        game.world.stepSimulation(1.0f / 60, 0);
        rec.step();  // 2: this step's inserts, removes and moves
        // The player circles the pile and shoots at it.
        const float angle = 0.01f * float(step);
        const btVector3 player(12 * std::cos(angle), 1.5f, 12 * std::sin(angle));
        for (int shot = 0; shot < 4; ++shot) {
            const btVector3 aim(float(shot) - 1.5f, 0.5f + 0.5f * float(shot), 0);
            btCollisionWorld::ClosestRayResultCallback closest(player, aim);
            rec.ray_test(player, aim, closest);  // 3: instead of game.world.rayTest(...)
            hits += closest.hasHit();
        }
        const btVector3 above(0.3f * float(step % 7) - 1, 20, 0.3f * float(step % 5) - 0.6f);
        const btVector3 below(above.x(), -1, above.z());
        btCollisionWorld::AllHitsRayResultCallback probe(above, below);
        rec.ray_test(above, below, probe);
    }
    rec.close();
    std::printf("recorded 600 steps, %zu bodies, %d of 2400 shots hit: %s\n", rec.live_count(), hits, path.c_str());
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const std::string path =
            argc >= 2 ? argv[1] : (std::filesystem::temp_directory_path() / "bullet_game.rcbscene").string();
        record_game(path);
        std::vector<const char*> advise = {argv[0], "advise", path.c_str()};
        for (int i = 2; i < argc; ++i) advise.push_back(argv[i]);
        return rcb::cli::main(int(advise.size()), const_cast<char**>(advise.data()));
    } catch (const rcb::InputError& e) {
        std::fprintf(stderr, "bullet_game: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bullet_game: %s\n", e.what());
        return 1;
    }
}

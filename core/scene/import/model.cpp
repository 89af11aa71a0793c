#include "core/scene/import/model.h"

#include <pthread.h>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <array>
#include <cmath>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <optional>
#include <vector>

#include "core/base/error.h"
#include "core/scene/import/nesting.h"
#include "core/scene/recording_io.h"

namespace rcb {
namespace {

/// The stack assimp runs on. Its parsers recurse per level of nesting (nesting.h bounds that for
/// the formats that nest in text), and for the formats nothing scans (FBX and other binaries) this
/// is the backstop: a thread stack is reserved address space, touched only as deep as the
/// recursion goes, so 256 MiB costs nothing for ordinary files.
constexpr std::size_t kImportStackBytes = std::size_t(256) << 20;

/// Runs `work` on a new thread with a `stack_bytes` stack and waits for it; an exception thrown by
/// `work` is rethrown here. (std::thread cannot set a stack size.)
void run_with_stack(std::size_t stack_bytes, const std::function<void()>& work) {
    struct Job {
        const std::function<void()>* work;
        std::exception_ptr error;
    } job{&work, nullptr};
    pthread_attr_t attr;
    if (pthread_attr_init(&attr) != 0) throw std::runtime_error("pthread_attr_init failed");
    int rc = pthread_attr_setstacksize(&attr, stack_bytes);
    pthread_t thread;
    if (rc == 0)
        rc = pthread_create(
            &thread, &attr,
            [](void* p) -> void* {
                auto* j = static_cast<Job*>(p);
                try {
                    (*j->work)();
                } catch (...) {
                    j->error = std::current_exception();
                }
                return nullptr;
            },
            &job);
    pthread_attr_destroy(&attr);
    if (rc != 0) throw std::runtime_error(std::string("cannot start the model import thread: ") + std::strerror(rc));
    pthread_join(thread, nullptr);
    if (job.error) std::rethrow_exception(job.error);
}

/// Calls `visit(node, world transform)` for every node, parents before children and children in
/// order (the order of a recursive walk), with an explicit stack: the depth of the hierarchy is
/// the file's to choose.
template <class Visit>
void for_each_node(const aiNode* root, Visit&& visit) {
    std::vector<std::pair<const aiNode*, aiMatrix4x4>> stack{{root, aiMatrix4x4()}};
    while (!stack.empty()) {
        const auto [n, parent] = stack.back();
        stack.pop_back();
        const aiMatrix4x4 world = parent * n->mTransformation;
        visit(n, world);
        for (unsigned c = n->mNumChildren; c-- > 0;) stack.push_back({n->mChildren[c], world});
    }
}

/// The oriented box of `mesh`'s local bounds under `world`, when `world` is scale, rotation and
/// translation (checked by mapping the local box's corners back) and the rotation is not the
/// identity; otherwise none.
std::optional<Shape> instance_obb(const aiMesh* mesh, const aiMatrix4x4& world) {
    aiVector3D lo = mesh->mVertices[0], hi = lo;
    for (unsigned v = 1; v < mesh->mNumVertices; ++v) {
        const aiVector3D& p = mesh->mVertices[v];
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    aiVector3D scaling, position;
    aiQuaternion q;
    world.Decompose(scaling, q, position);
    if (std::abs(q.x) < 1e-6f && std::abs(q.y) < 1e-6f && std::abs(q.z) < 1e-6f) return std::nullopt;
    const aiVector3D c_local = (lo + hi) * 0.5f, h_local = (hi - lo) * 0.5f;
    const aiVector3D c = world * c_local;
    const Vec3 half{std::abs(scaling.x) * h_local.x, std::abs(scaling.y) * h_local.y, std::abs(scaling.z) * h_local.z};
    const Shape obb = Shape::obb({c.x, c.y, c.z}, half, {q.w, q.x, q.y, q.z});
    if (!shape_problem(obb, std::numeric_limits<double>::max()).empty()) return std::nullopt;
    // Each corner of the local box, transformed, must land on the obb's corresponding corner
    // (within float rounding of the scene's magnitude): otherwise the matrix shears.
    const std::array<Vec3d, 3> axis = obb_axes<double>(obb);
    for (int k = 0; k < 8; ++k) {
        const aiVector3D corner{k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z};
        const aiVector3D w = world * corner;
        const Vec3d d = Vec3d{w.x, w.y, w.z} - Vec3d{c.x, c.y, c.z};
        const double m = 1e-4 * (std::sqrt(dot(d, d)) + std::abs(double(c.x)) + std::abs(double(c.y)) +
                                 std::abs(double(c.z)) + 1e-30);
        for (int a = 0; a < 3; ++a)
            if (std::abs(dot(d, axis[a])) > double(half[a]) + m) return std::nullopt;
    }
    return obb;
}

std::vector<Object> read_model(const std::string& path, bool triangles, bool obbs, ModelSummary& sum) {
    Assimp::Importer importer;
    // Triangulate so polygons become triangles; nothing else changes the geometry.
    const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate);
    if (!scene || !scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
        throw InputError(path + ": assimp: " + quoted_excerpt(importer.GetErrorString(), 200));
    sum.meshes = scene->mNumMeshes;

    // Count the objects before allocating them (a mesh instanced by many nodes multiplies).
    std::uint64_t estimate = 0;
    for_each_node(scene->mRootNode, [&](const aiNode* n, const aiMatrix4x4&) {
        for (unsigned i = 0; i < n->mNumMeshes; ++i)
            estimate += triangles ? scene->mMeshes[n->mMeshes[i]]->mNumFaces : 1;
    });
    if (estimate > kMaxSceneObjects)
        throw InputError(path + ": " + (triangles ? "triangles" : "instances") + " mode would make " +
                         std::to_string(estimate) + " objects, more than the limit of " +
                         std::to_string(kMaxSceneObjects) + " per scene (kMaxSceneObjects, scene.h)" +
                         (triangles ? "; try --model-mode instances" : ""));

    std::vector<Object> out;
    out.reserve(estimate);
    auto add = [](Aabb& box, const aiVector3D& p) {
        const Vec3 v{float(p.x), float(p.y), float(p.z)};
        box = {min(box.min, v), max(box.max, v)};
    };
    const aiNode* current = nullptr;
    auto push = [&](const Aabb& box) {
        if (!is_finite(box.min) || !is_finite(box.max)) return;  // a degenerate or broken vertex
        out.push_back(Object{Uid(out.size()), box});
        if (!box_problem(box).empty())
            check_object(out.back(), path + ": node " + quoted_excerpt(current->mName.C_Str()));
    };
    for_each_node(scene->mRootNode, [&](const aiNode* n, const aiMatrix4x4& world) {
        current = n;
        for (unsigned i = 0; i < n->mNumMeshes; ++i) {
            const aiMesh* mesh = scene->mMeshes[n->mMeshes[i]];
            ++sum.instances;
            if (triangles) {
                // Each object is its triangle in world space (the node's transform applied, as
                // for the boxes), the box its bounds. Degenerate triangles stay (valid shapes); a
                // vertex that is not finite, in the file or once transformed, is an error.
                for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
                    const aiFace& face = mesh->mFaces[f];
                    if (face.mNumIndices != 3) continue;
                    Vec3 p[3];
                    for (unsigned k = 0; k < 3; ++k) {
                        const aiVector3D v = world * mesh->mVertices[face.mIndices[k]];
                        p[k] = {float(v.x), float(v.y), float(v.z)};
                        if (!is_finite(p[k]))
                            throw InputError(path + ": node " + quoted_excerpt(n->mName.C_Str()) + ": mesh " +
                                             quoted_excerpt(mesh->mName.C_Str()) + " triangle " + std::to_string(f) +
                                             " has a non-finite vertex");
                    }
                    out.push_back(shaped_object(Uid(out.size()), Shape::triangle(p[0], p[1], p[2])));
                    // The box is the vertices' exact bounds: its check names a coordinate out of range.
                    if (!box_problem(out.back().box).empty())
                        check_object(Object{out.back().uid, out.back().box},
                                     path + ": node " + quoted_excerpt(n->mName.C_Str()));
                    ++sum.triangles;
                }
            } else {
                if (mesh->mNumVertices == 0) continue;
                Aabb box = Aabb::empty();
                for (unsigned v = 0; v < mesh->mNumVertices; ++v) add(box, world * mesh->mVertices[v]);
                const std::size_t before = out.size();
                push(box);
                // In obbs mode a rotated instance is the oriented box of its mesh's own bounds under
                // the node's transform; a transform that does not decompose into scale, rotation and
                // translation (shear), or that does not rotate, keeps the world-space box.
                if (obbs && out.size() > before) {
                    const std::optional<Shape> obb = instance_obb(mesh, world);
                    if (obb && shape_problem(*obb, kMaxCoordinate).empty())
                        out.back() = shaped_object(out.back().uid, *obb);
                }
            }
        }
    });
    return out;  // the importer frees assimp's scene here, on this thread's stack too
}

}  // namespace

bool is_model_extension(const std::string& ext) {
    Assimp::Importer importer;
    return !ext.empty() && ext != ".csv" && ext != ".bsp" && ext != ".pk3" && importer.IsExtensionSupported(ext);
}

std::vector<Object> import_model(const std::string& path, const std::string& mode, ModelSummary* summary) {
    if (mode != "instances" && mode != "obbs" && mode != "triangles")
        throw InputError(path + ": model mode " + quoted_excerpt(mode) + ": expected instances, obbs or triangles");
    check_model_nesting(path);
    ModelSummary local;
    ModelSummary& sum = summary ? *summary : local;
    std::vector<Object> out;
    run_with_stack(kImportStackBytes, [&] { out = read_model(path, mode == "triangles", mode == "obbs", sum); });
    return out;
}

}  // namespace rcb

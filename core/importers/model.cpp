#include "core/importers/model.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include "core/error.h"

namespace rcb {
namespace {

struct Walk {
    const aiScene* scene;
    bool triangles;
    std::vector<Object>& out;
    ModelSummary& sum;

    void node(const aiNode* n, const aiMatrix4x4& parent) {
        const aiMatrix4x4 world = parent * n->mTransformation;
        for (unsigned i = 0; i < n->mNumMeshes; ++i) {
            const aiMesh* mesh = scene->mMeshes[n->mMeshes[i]];
            ++sum.instances;
            if (triangles) {
                for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
                    const aiFace& face = mesh->mFaces[f];
                    if (face.mNumIndices != 3) continue;
                    Aabb box = Aabb::empty();
                    for (unsigned k = 0; k < 3; ++k) add(box, world * mesh->mVertices[face.mIndices[k]]);
                    push(box);
                    ++sum.triangles;
                }
            } else {
                if (mesh->mNumVertices == 0) continue;
                Aabb box = Aabb::empty();
                for (unsigned v = 0; v < mesh->mNumVertices; ++v) add(box, world * mesh->mVertices[v]);
                push(box);
            }
        }
        for (unsigned c = 0; c < n->mNumChildren; ++c) node(n->mChildren[c], world);
    }
    static void add(Aabb& box, const aiVector3D& p) {
        const Vec3 v{float(p.x), float(p.y), float(p.z)};
        box = {min(box.min, v), max(box.max, v)};
    }
    void push(const Aabb& box) {
        if (!is_finite(box.min) || !is_finite(box.max)) return;  // a degenerate or broken vertex
        out.push_back(Object{Uid(out.size()), box});
    }
};

}  // namespace

bool is_model_extension(const std::string& ext) {
    Assimp::Importer importer;
    return !ext.empty() && ext != ".csv" && ext != ".bsp" && ext != ".pk3" && importer.IsExtensionSupported(ext);
}

std::vector<Object> import_model(const std::string& path, const std::string& mode, ModelSummary* summary) {
    if (mode != "instances" && mode != "triangles")
        throw InputError(path + ": model mode '" + mode + "': expected instances or triangles");
    Assimp::Importer importer;
    // Triangulate so polygons become triangles; nothing else changes the geometry.
    const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate);
    if (!scene || !scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
        throw InputError(path + ": assimp: " + std::string(importer.GetErrorString()));
    ModelSummary local;
    ModelSummary& sum = summary ? *summary : local;
    sum.meshes = scene->mNumMeshes;
    std::vector<Object> out;
    Walk{scene, mode == "triangles", out, sum}.node(scene->mRootNode, aiMatrix4x4());
    return out;
}

}  // namespace rcb

// scene.hpp — the scene model: a CSG tree of primitives and operators as flat, immutable arrays
// (DESIGN.md §1–2). Nodes are stored in post-order (children before parents, left subtree before
// right subtree, root last) with 32-bit indices; no pointers and no recursion anywhere, so trees
// may be millions of levels deep.
//
// Thread-safety: a Scene is immutable once built; any number of threads may read it.
#pragma once

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "../../shaders/shared/sdf_math.h"

namespace sdfprune {

using math::vec2;
using math::vec3;
using math::vec4;

inline constexpr uint32_t kNone = 0xffffffffu;
// Node indices must fit the 31 bits of a tape word.
inline constexpr uint32_t kMaxNodes = math::kTapeNodeMask;

// Thrown for invalid input: malformed scene files, invalid parameters. The message is one line.
struct SceneError : std::runtime_error {
    using std::runtime_error::runtime_error;
};
// A SceneError about one node of a description array (build_scene), so loaders can name it.
struct SceneNodeError : SceneError {
    SceneNodeError(uint32_t desc_index, const std::string& what)
        : SceneError("node " + std::to_string(desc_index) + ": " + what),
          node(desc_index),
          reason(what) {}
    uint32_t node;
    std::string reason;
};

struct Aabb {
    vec3 min;
    vec3 max;
};

// A row-major 3x4 affine map: y = M·x + t, rows (m[0..3]), (m[4..7]), (m[8..11]).
struct Affine {
    float m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    static Affine identity() { return {}; }
    static Affine translation(vec3 t);
    static Affine scaling(vec3 s);
    // Rotation by `radians` about `axis` (need not be normalized).
    static Affine rotation(vec3 axis, float radians);
    vec3 apply(vec3 p) const;
    // this · b (apply b first).
    Affine compose(const Affine& b) const;
    // The inverse map; throws SceneError if the linear part is singular.
    Affine inverse() const;
    bool operator==(const Affine&) const = default;
};

// Spectral norm (largest singular value) of the linear part: the Lipschitz factor of the map.
float spectral_norm(const Affine& a);

// The kind-specific parameters of a primitive, in the scene format's own terms.
struct PrimitiveShape {
    float radius = 0;   // sphere, cylinder, cone (base), capsule, rounded_cylinder, capped_cone,
                        // hex_prism (circumradius), octahedron
    float height = 0;   // cylinder, cone, rounded_cylinder (full, along y); capsule (segment)
    vec3 sides;         // box: full lengths
    vec4 bevel;         // box: xz corner radii, quadrants (+x+z, +x-z, -x+z, -x-z)
    float round_x = 0;  // box: rounding of the top (+y) edges
    float round_y = 0;  // box: rounding of the bottom (-y) edges
    float major_radius = 0;  // torus, in the xz plane
    float minor_radius = 0;  // torus
    float rounding = 0;      // rounded_cylinder: rim radius
    float top_radius = 0;    // capped_cone: radius at y = +height/2 (radius: at -height/2)
    vec3 normal;             // plane: outward normal (any length > 0)
    float offset = 0;        // plane: signed distance of the plane from the origin along normal
    bool operator==(const PrimitiveShape&) const = default;
};

// One node as a scene file or the builder describes it, before the tree is flattened.
struct SceneNodeDesc {
    uint32_t kind = math::kPrimSphere;  // math::kPrim* or math::kOp*
    uint32_t left = kNone;              // operators: indices into the description array
    uint32_t right = kNone;
    float blend = 0;               // operators: blend radius k >= 0
    Affine matrix;                 // this node's step of the world->local map
    PrimitiveShape shape;          // primitives
    vec3 color{0.8f, 0.8f, 0.8f};  // primitives, in [0, 1]
};

// A per-primitive bound used by pruning: if the primitive's world->local map is a similarity of
// scale `scale` (> 0) sending `centre` to the local origin, then `f0` is the local SDF at the
// origin and `rho` the radius of a local ball about the origin that holds the whole shape.
// scale <= 0 means the map is not a similarity and only the Lipschitz bound applies.
struct PrimitiveBound {
    vec3 centre;
    float scale = 0;
    float f0 = 0;
    float rho = 0;
};

struct Scene {
    Aabb aabb;

    // Per node, post-order; root = size() - 1.
    std::vector<uint32_t> kind;  // math::kPrim* or math::kOp*
    std::vector<uint32_t> left;  // operators: child node; primitives: kNone
    std::vector<uint32_t> right;
    std::vector<uint32_t> parent;     // kNone at the root
    std::vector<uint8_t> negated;     // 1 if the node is the right operand of a difference
    std::vector<float> blend;         // operators: blend radius k; primitives: 0
    std::vector<float> lipschitz;     // bound on |∇f| of the node's function (operators: max)
    std::vector<uint32_t> primitive;  // primitives: index into the per-primitive arrays
    std::vector<Affine> local;        // the node's own matrix, as loaded (for saving)

    // Per primitive, in node order.
    std::vector<uint32_t> primitive_node;       // node of each primitive
    std::vector<math::PrimitiveParams> params;  // baked world->local map + parameters
    std::vector<PrimitiveShape> shape;
    std::vector<vec3> color;
    std::vector<PrimitiveBound> bound;

    // The tape of the whole tree: every node in post-order with its sign (see eval.hpp).
    std::vector<uint32_t> full_tape;
    // Largest value-stack depth a post-order evaluation of the tree needs; a pruned tape of the
    // tree never needs more (its ancestors are a subset of the full tree's).
    uint32_t max_stack = 1;

    uint32_t size() const { return static_cast<uint32_t>(kind.size()); }
    uint32_t root() const { return size() - 1; }
    uint32_t primitive_count() const { return static_cast<uint32_t>(primitive_node.size()); }
    bool is_primitive(uint32_t node) const { return kind[node] < math::kPrimitiveKindCount; }
};

// Flattens a described tree into a Scene: canonical post-order, matrices composed from the root
// down (parent · child) and baked per primitive, Lipschitz bounds, signs. Validates parameters
// and throws SceneError naming the node (by description index) on invalid input. Nodes not
// reachable from `root` are ignored; a description used twice is duplicated.
Scene build_scene(std::span<const SceneNodeDesc> nodes, uint32_t root, const Aabb& aabb);

// Checks one primitive's or operator's parameters; returns "" when valid, else the reason.
std::string validate_node(const SceneNodeDesc& node);

// Whether the scene's shape is bounded, judged from the tree (conservatively): a bounded
// primitive is (a plane is not); a union when both operands are; an intersection when either
// is; a difference when its left operand is. Blending does not change the answer.
bool shape_is_bounded(const Scene& scene);

// The AABB used when a scene gives none (SceneBuilder::build without one, generators): the hull
// of the bounded primitives' world boxes (from each one's local box), padded by `pad` times its
// size on each side. Half-spaces add nothing: when shape_is_bounded holds, the shape lies in the
// union of its bounded primitives, so in that hull. Throws SceneError when it does not hold
// (e.g. a plane alone, or a union with a plane): such a scene needs an explicit AABB.
Aabb bounding_box(const Scene& scene, float pad = 0.05f);

// Summary figures of a scene.
struct SceneInfo {
    uint32_t nodes = 0, primitives = 0, operators = 0;
    uint32_t depth = 0;  // edges on the longest root-to-leaf path
    float max_lipschitz = 0;
    uint32_t per_primitive_kind[math::kPrimitiveKindCount] = {};
    uint32_t unions = 0, intersections = 0, differences = 0;
    uint32_t smooth_operators = 0;  // operators with k > 0
};
SceneInfo scene_info(const Scene& scene);

// Names used in scene files and reports.
const char* primitive_kind_name(uint32_t kind);  // "sphere", "box", ...
const char* operator_kind_name(uint32_t kind);   // "union", "inter", "sub"
// kNone if unknown.
uint32_t primitive_kind_from_name(std::string_view name);
uint32_t operator_kind_from_name(std::string_view name);

}  // namespace sdfprune

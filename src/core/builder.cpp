// builder.cpp — the C++ construction API: an arena of shape nodes, flattened into scene
// descriptions with placements baked into each primitive's world->local matrix.
#include "sdfprune/builder.hpp"

namespace sdfprune {

Shape SceneBuilder::add(Node n) {
    nodes_.push_back(n);
    return Shape(this, uint32_t(nodes_.size() - 1));
}

namespace {
SceneNodeDesc primitive_desc(uint32_t kind, const PrimitiveShape& shape) {
    SceneNodeDesc d;
    d.kind = kind;
    d.shape = shape;
    return d;
}
}  // namespace

Shape SceneBuilder::primitive(uint32_t kind, const PrimitiveShape& shape) {
    if (kind >= math::kPrimitiveKindCount) throw SceneError("unknown primitive");
    return add({primitive_desc(kind, shape), {}});
}

Shape SceneBuilder::sphere(float radius) {
    PrimitiveShape s;
    s.radius = radius;
    return add({primitive_desc(math::kPrimSphere, s), {}});
}

Shape SceneBuilder::box(vec3 sides, vec4 bevel, float round_top, float round_bottom) {
    PrimitiveShape s;
    s.sides = sides;
    s.bevel = bevel;
    s.round_x = round_top;
    s.round_y = round_bottom;
    return add({primitive_desc(math::kPrimBox, s), {}});
}

Shape SceneBuilder::cylinder(float radius, float height) {
    PrimitiveShape s;
    s.radius = radius;
    s.height = height;
    return add({primitive_desc(math::kPrimCylinder, s), {}});
}

Shape SceneBuilder::cone(float radius, float height) {
    PrimitiveShape s;
    s.radius = radius;
    s.height = height;
    return add({primitive_desc(math::kPrimCone, s), {}});
}

Shape SceneBuilder::capsule(float radius, float height) {
    PrimitiveShape s;
    s.radius = radius;
    s.height = height;
    return add({primitive_desc(math::kPrimCapsule, s), {}});
}

Shape SceneBuilder::torus(float major_radius, float minor_radius) {
    PrimitiveShape s;
    s.major_radius = major_radius;
    s.minor_radius = minor_radius;
    return add({primitive_desc(math::kPrimTorus, s), {}});
}

Shape SceneBuilder::scene(const Scene& scene) {
    // Each primitive's whole world->local map (the matrices composed from the root down, as
    // build_scene does) becomes its placement; operators get none. Parents come after their
    // children in post-order, so a downward pass runs from the root to index 0.
    const uint32_t n = scene.size();
    std::vector<Affine> world(n);
    for (uint32_t i = n; i-- > 0;)
        world[i] = scene.parent[i] == kNone ? scene.local[i]
                                            : world[scene.parent[i]].compose(scene.local[i]);
    std::vector<uint32_t> id(n);
    for (uint32_t i = 0; i < n; ++i) {
        Node node;
        node.desc.kind = scene.kind[i];
        if (scene.is_primitive(i)) {
            const uint32_t p = scene.primitive[i];
            node.desc.shape = scene.shape[p];
            node.desc.color = scene.color[p];
            if (!(world[i] == Affine())) node.placement = world[i].inverse();
        } else {
            node.desc.left = id[scene.left[i]];
            node.desc.right = id[scene.right[i]];
            node.desc.blend = scene.blend[i];
        }
        id[i] = add(node).id_;
    }
    return Shape(this, id[scene.root()]);
}

Shape SceneBuilder::rounded_cylinder(float radius, float height, float rounding) {
    PrimitiveShape s;
    s.radius = radius;
    s.height = height;
    s.rounding = rounding;
    return add({primitive_desc(math::kPrimRoundedCylinder, s), {}});
}

Shape SceneBuilder::capped_cone(float radius, float top_radius, float height) {
    PrimitiveShape s;
    s.radius = radius;
    s.top_radius = top_radius;
    s.height = height;
    return add({primitive_desc(math::kPrimCappedCone, s), {}});
}

Shape SceneBuilder::hex_prism(float radius, float height) {
    PrimitiveShape s;
    s.radius = radius;
    s.height = height;
    return add({primitive_desc(math::kPrimHexPrism, s), {}});
}

Shape SceneBuilder::octahedron(float radius) {
    PrimitiveShape s;
    s.radius = radius;
    return add({primitive_desc(math::kPrimOctahedron, s), {}});
}

Shape SceneBuilder::plane(vec3 normal, float offset) {
    PrimitiveShape s;
    s.normal = normal;
    s.offset = offset;
    return add({primitive_desc(math::kPrimPlane, s), {}});
}

Shape SceneBuilder::combine(uint32_t kind, Shape a, Shape b, float k) {
    if (a.builder_ != this || b.builder_ != this)
        throw SceneError("shapes from another builder cannot be combined");
    if (kind < math::kOpUnion || kind > math::kOpDifference) throw SceneError("unknown operator");
    SceneNodeDesc d;
    d.kind = kind;
    d.left = a.id_;
    d.right = b.id_;
    d.blend = k;
    return add({d, {}});
}

std::vector<SceneNodeDesc> SceneBuilder::describe(Shape root) const {
    if (root.builder_ != this || root.id_ >= nodes_.size())
        throw SceneError("shape does not belong to this builder");
    // Depth-first from the root, carrying the composed placement and any color override; each
    // visit emits a fresh description, so shared shapes are duplicated into a tree.
    struct Visit {
        uint32_t node;
        uint32_t slot;  // index of the emitted description that refers to this child
        bool is_right;
        Affine placement;  // local -> world, composed
        bool colored;
        vec3 color;
    };
    std::vector<SceneNodeDesc> out;
    std::vector<Visit> stack{{root.id_, kNone, false, Affine(), false, {}}};
    while (!stack.empty()) {
        Visit v = stack.back();
        stack.pop_back();
        const Node& n = nodes_[v.node];
        if (out.size() >= kMaxNodes) throw SceneError("scene has too many nodes");
        const uint32_t self = uint32_t(out.size());
        out.push_back(n.desc);
        if (v.slot != kNone) (v.is_right ? out[v.slot].right : out[v.slot].left) = self;
        const Affine placement = v.placement.compose(n.placement);
        const bool colored = v.colored || n.color_override;
        const vec3 color = v.colored ? v.color : n.desc.color;
        if (n.desc.kind >= math::kOpUnion) {
            out[self].matrix = Affine();
            stack.push_back({n.desc.right, self, true, placement, colored, color});
            stack.push_back({n.desc.left, self, false, placement, colored, color});
        } else {
            out[self].matrix = placement.inverse();
            if (colored) out[self].color = color;
        }
    }
    // build_scene wants the root's index; put it last by reversing (children indices remap).
    const uint32_t n = uint32_t(out.size());
    std::vector<SceneNodeDesc> reversed(out.rbegin(), out.rend());
    for (SceneNodeDesc& d : reversed) {
        if (d.left != kNone) d.left = n - 1 - d.left;
        if (d.right != kNone) d.right = n - 1 - d.right;
    }
    return reversed;
}

Scene SceneBuilder::build(Shape root, const Aabb& aabb) const {
    std::vector<SceneNodeDesc> d = describe(root);
    return build_scene(d, uint32_t(d.size() - 1), aabb);
}

Scene SceneBuilder::build(Shape root) const {
    std::vector<SceneNodeDesc> d = describe(root);
    // Build once over a placeholder box to measure the primitives, then over their bounds.
    Scene s = build_scene(d, uint32_t(d.size() - 1), {vec3(-1.0f), vec3(1.0f)});
    s.aabb = bounding_box(s);
    return s;
}

Shape Shape::transformed(const Affine& placement) const {
    SceneBuilder::Node n = builder_->nodes_.at(id_);
    n.placement = placement.compose(n.placement);
    return builder_->add(n);
}

Shape Shape::translated(vec3 t) const {
    return transformed(Affine::translation(t));
}
Shape Shape::rotated(vec3 axis, float radians) const {
    return transformed(Affine::rotation(axis, radians));
}
Shape Shape::scaled(float s) const {
    return transformed(Affine::scaling(vec3(s)));
}
Shape Shape::scaled(vec3 s) const {
    return transformed(Affine::scaling(s));
}

Shape Shape::colored(vec3 rgb) const {
    SceneBuilder::Node n = builder_->nodes_.at(id_);
    n.desc.color = rgb;
    n.color_override = true;
    return builder_->add(n);
}

Shape operator|(Shape a, Shape b) {
    return a.builder()->combine(math::kOpUnion, a, b, 0);
}
Shape operator&(Shape a, Shape b) {
    return a.builder()->combine(math::kOpIntersection, a, b, 0);
}
Shape operator-(Shape a, Shape b) {
    return a.builder()->combine(math::kOpDifference, a, b, 0);
}
Shape smooth_union(Shape a, Shape b, float k) {
    return a.builder()->combine(math::kOpUnion, a, b, k);
}
Shape smooth_intersection(Shape a, Shape b, float k) {
    return a.builder()->combine(math::kOpIntersection, a, b, k);
}
Shape smooth_difference(Shape a, Shape b, float k) {
    return a.builder()->combine(math::kOpDifference, a, b, k);
}

}  // namespace sdfprune

// builder.hpp — writing scenes in C++: primitives, placements, and CSG with |, &, - and their
// smooth variants. Used by tests and by the scene generators.
//
//   SceneBuilder b;
//   Shape body = b.capsule(0.3f, 1.0f).colored({0.9f, 0.6f, 0.4f});
//   Shape head = b.sphere(0.35f).translated({0, 0.9f, 0});
//   Scene scene = b.build(smooth_union(body, head, 0.1f));
//
// A Shape is a handle into its builder (cheap to copy); using a shape twice duplicates it in the
// built tree. Placements (translated, rotated, scaled) move the shape in the world; they are
// baked into the primitives' world->local matrices when the scene is built. A builder and its
// shapes are not thread-safe.
#pragma once

#include "scene.hpp"

namespace sdfprune {

class SceneBuilder;

class Shape {
  public:
    Shape() = default;
    Shape translated(vec3 t) const;
    Shape rotated(vec3 axis, float radians) const;
    Shape scaled(float s) const;
    Shape scaled(vec3 s) const;  // non-uniform: the scene stays exact through Lipschitz bounds
    // Applies `placement` (a local->world map) after the shape's current placement.
    Shape transformed(const Affine& placement) const;
    // Sets the color of every primitive in the shape (components in [0, 1]).
    Shape colored(vec3 rgb) const;

    uint32_t id() const { return id_; }
    SceneBuilder* builder() const { return builder_; }

  private:
    friend class SceneBuilder;
    Shape(SceneBuilder* b, uint32_t id) : builder_(b), id_(id) {}
    SceneBuilder* builder_ = nullptr;
    uint32_t id_ = kNone;
};

class SceneBuilder {
  public:
    Shape sphere(float radius);
    // Full side lengths; optional xz corner radii (+x+z, +x-z, -x+z, -x-z) and edge rounding
    // of the top (+y) and bottom (-y) rims.
    Shape box(vec3 sides, vec4 bevel = {}, float round_top = 0, float round_bottom = 0);
    Shape cylinder(float radius, float height);  // along y, centred
    Shape cone(float radius, float height);     // base (radius) at y = -height/2, apex at +height/2
    Shape capsule(float radius, float height);  // inner segment of length `height` along y
    Shape torus(float major_radius, float minor_radius);  // in the xz plane
    // Cylinder along y, centred, both rims rounded by `rounding` <= min(radius, height / 2).
    Shape rounded_cylinder(float radius, float height, float rounding);
    // Cone frustum along y, centred: `radius` at y = -height/2, `top_radius` at +height/2
    // (either may be 0).
    Shape capped_cone(float radius, float top_radius, float height);
    // Hexagonal prism along y, centred: vertices at distance `radius` from the axis (two of
    // them on the x axis), full `height`.
    Shape hex_prism(float radius, float height);
    Shape octahedron(float radius);  // |x| + |y| + |z| <= radius: vertices on the axes
    // The half-space dot(p, normal) <= offset·|normal| (the side `normal` points away from),
    // unbounded: combine it with bounded shapes (intersection, or subtract it) or build the
    // scene over an explicit AABB.
    Shape plane(vec3 normal, float offset = 0);
    // Any kind of primitives.hpp's table with its fields in `shape` (checked when built).
    Shape primitive(uint32_t kind, const PrimitiveShape& shape);

    // A built or loaded scene as a shape of this builder: its tree with each node's matrix
    // (as a placement, its inverse) and colors; its AABB is not kept. Throws SceneError when a
    // node's matrix is singular.
    Shape scene(const Scene& scene);

    // kind: math::kOpUnion, kOpIntersection or kOpDifference; k >= 0 is the blend radius.
    Shape combine(uint32_t kind, Shape a, Shape b, float k);

    // Flattens the shape into a scene over `aabb`, or over bounding_box(...) when omitted.
    // Throws SceneError on invalid parameters.
    Scene build(Shape root) const;
    Scene build(Shape root, const Aabb& aabb) const;

    // The node descriptions `root` expands to (placements baked into primitive matrices,
    // operators with identity matrices), with the root last.
    std::vector<SceneNodeDesc> describe(Shape root) const;

  private:
    friend class Shape;
    struct Node {
        SceneNodeDesc desc;           // desc.matrix unused here
        Affine placement;             // local -> parent frame
        bool color_override = false;  // desc.color applies to every primitive below
    };
    Shape add(Node n);
    std::vector<Node> nodes_;
};

Shape operator|(Shape a, Shape b);  // union
Shape operator&(Shape a, Shape b);  // intersection
Shape operator-(Shape a, Shape b);  // difference: a minus b
Shape smooth_union(Shape a, Shape b, float k);
Shape smooth_intersection(Shape a, Shape b, float k);
Shape smooth_difference(Shape a, Shape b, float k);

}  // namespace sdfprune

// mesh.hpp — isosurface extraction (DESIGN.md §6 "meshing"): the surface f = 0 of a scene as a
// closed, consistently oriented triangle mesh, and its STL / PLY / OBJ writers.
//
// Method: marching tetrahedra on a regular grid of resolution³ cubes spanning the scene's AABB.
// Every cube is split into the 6 tetrahedra of the Kuhn (Freudenthal) triangulation, all sharing
// the cube's main diagonal (0,0,0)-(1,1,1); neighbouring cubes then split their common face
// along the same diagonal, so the tetrahedra tile space and there are no ambiguous cases. One
// vertex per tetrahedron edge (grid edge, face or cube diagonal) whose ends differ in sign,
// shared by every triangle using that edge.
//
// Guarantees (for any scene, not only closed shapes):
//   - closed 2-manifold: every undirected edge is used by exactly two triangles, once in each
//     direction; no duplicate triangles; no triangle has two equal vertex indices;
//   - outward orientation: counter-clockwise seen from outside (f > 0), so the signed volume
//     is positive;
//   - shapes cut by the AABB are capped: grid corners on the AABB's faces count as outside;
//   - deterministic: the same mesh (same vertex and triangle order, same bits) for any thread
//     count, and the same mesh from the pruned grid and from the full tree (see mesh() below).
// Sign convention: f < 0 is inside; f == 0 counts as outside. A vertex lies where the linear
// interpolation of f along its edge is zero, kept at least kMinEdgeFraction of the edge away
// from both grid corners, so triangles never have zero area at ordinary resolutions (at very high
// resolutions over an AABB far from the origin, float spacing may still merge nearby vertices'
// positions: indices stay distinct and the mesh stays manifold).
//
// Cost: the pruned version visits only cubes overlapping near-field cells of the pruned grid
// (a far-field cell has f != 0 everywhere in it, so no surface), plus the cubes where an inside
// far-field cell meets the AABB (their cap). Where the grid's cells are made of 2³ to 8³ cubes,
// it drops inside each cell the boxes of cubes whose centre value clears their Lipschitz reach,
// halving them down to single cubes, so the cubes kept do not depend on the pruning grid and a
// coarse grid (default_mesh_grid) is the fastest. It evaluates each corner of the cubes kept
// once, with the tape of a near-field cell holding it, the corners of a cell together in vector
// lanes (eval_tape_lanes). Memory: corners are stored in 8³ bricks allocated only where needed,
// about 9.2 bytes per corner of an allocated brick, 13.2 when the bricks keep the cells' tapes (the
// naive version allocates all bricks: ~9.2·(resolution+1)³ bytes, 156 MB at 256), plus
// 4·(resolution/8+1)³ bytes of brick table, plus the mesh.
//
// Thread-safety: mesh() functions are pure (they read the scene / grid, which may be shared);
// they run on oneTBB with options.threads workers.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "prune.hpp"
#include "scene.hpp"

namespace sdfprune {

// Largest accepted MeshOptions::resolution.
inline constexpr uint32_t kMaxMeshResolution = 2048;
// A vertex stays at least this fraction of its grid edge away from both ends.
inline constexpr float kMinEdgeFraction = 1e-3f;

// The pruning grid that meshes at `resolution` cubes per axis fastest, the default of the CLI
// and of Python: the resolution divided by the largest of 8, 4 and 2 that divides it (else the
// resolution). The mesher drops, inside each near-field cell, the boxes of cubes whose centre
// value clears their Lipschitz reach, halving them down to single cubes, so a coarse grid costs
// little in the mesher and much less to prune. Measured on molecule, trees and the Python
// quick-start scene (BENCHMARKS.md).
constexpr uint32_t default_mesh_grid(uint32_t resolution) {
    for (const uint32_t m : {8u, 4u, 2u})
        if (resolution % m == 0) return resolution / m;
    return resolution;
}

// An indexed triangle mesh, in the scene's world units.
struct Mesh {
    std::vector<vec3> vertices;
    // 3 vertex indices per triangle, counter-clockwise seen from outside.
    std::vector<uint32_t> triangles;
    size_t triangle_count() const { return triangles.size() / 3; }
};

struct MeshOptions {
    uint32_t resolution = 256;  // cubes per axis over the scene's AABB, 1..kMaxMeshResolution
    int threads = 0;            // worker threads; 0 = all hardware threads
    // Called from the calling thread with the fraction done in [0, 1]; may be empty.
    std::function<void(double)> progress;
    // When set and true, mesh() stops early and throws MeshCancelled.
    const std::atomic<bool>* cancel = nullptr;
};

struct MeshCancelled : std::runtime_error {
    MeshCancelled() : std::runtime_error("meshing cancelled") {}
};

struct MeshStats {
    uint32_t resolution = 0;
    uint64_t cubes_visited = 0;      // cubes considered for triangles (naive: resolution³)
    uint64_t corners_evaluated = 0;  // SDF evaluations (naive: (resolution + 1)³)
    uint64_t brick_bytes = 0;        // memory held by the corner bricks
    double ms = 0;                   // wall time of mesh()
};

// The surface of the scene `grid` was built from, evaluating only near the surface: cubes lying
// in far-field cells are skipped; every corner of the other cubes is evaluated once with the
// tape of a near-field cell holding it. Near-field tapes return the full tree's values bit for
// bit, so the result equals mesh(grid.scene(), options) (as far as the grid's far-field
// guarantee holds: sign(f) known over each far-field cell). The grid's resolution need not
// divide options.resolution, but default_mesh_grid(options.resolution) is the fastest (cells of
// up to 8³ cubes); where it does not divide it, each corner looks up its cell, and one held by
// far-field cells only (rare, except on caps) costs a full-tree evaluation. Throws
// std::invalid_argument for a bad resolution, MeshCancelled when cancelled.
Mesh mesh(const PrunedGrid& grid, const MeshOptions& options = {}, MeshStats* stats = nullptr);

// The naive baseline: the full tree at every one of the (resolution + 1)³ grid corners, with
// the same evaluation loop and threading as the pruned version.
Mesh mesh(const Scene& scene, const MeshOptions& options = {}, MeshStats* stats = nullptr);

// ---- writers ---------------------------------------------------------------------------------

enum class MeshFormat {
    kStl,  // binary STL: 80-byte header, uint32 count, per triangle a unit normal, 3 vertices
           // (float32, little endian) and a zero uint16; vertices are not shared (the format has
           // no indices)
    kPly,  // binary little-endian PLY: float x y z per vertex, faces as "list uchar int"
    kObj,  // Wavefront OBJ text: "v x y z" lines, then "f a b c" with 1-based indices
};

// The format named by a path's extension (.stl, .ply, .obj, any case); throws IoError (io.hpp)
// for any other.
MeshFormat mesh_format_of(const std::string& path);

// The file's bytes. STL has room for 2³²−1 triangles, PLY and OBJ for 2³¹−1 vertices; larger
// meshes throw std::length_error.
std::string encode_mesh(const Mesh& mesh, MeshFormat format);

// Writes the mesh to `path` atomically (temporary file, then rename), in the format of its
// extension. Throws IoError for an unknown extension or a failed write, leaving no file.
void write_mesh(const Mesh& mesh, const std::string& path);

}  // namespace sdfprune

// vdb.hpp — writing a discretized SDF (discretize.hpp) as an OpenVDB level set (.vdb) that
// Blender, Houdini and OpenVDB's own tools open.
//
// The file holds one openvdb::FloatGrid named "surface", class GRID_LEVEL_SET:
//   - transform: voxel (i, j, k) is the centre of cell (i, j, k) of the n³ grid, i.e. a linear
//     map with voxel size = cell size, translated by aabb.min + cell/2. A cubic AABB gives cubic
//     voxels (a uniform scale map). A non-cubic AABB (molecule.json's is 2 × 2 × 2.2) gives box
//     cells and so a per-axis scale: the file then holds exactly the n³ samples, no resampling.
//     Readers that place voxels through the transform (meshing, rendering) handle it; OpenVDB
//     tools that require uniform voxels (level-set tracking and filtering) need the grid
//     resampled to cubic voxels first. Use a cubic AABB when that matters.
//   - narrow band: only samples with |f| < background are stored, as active voxels;
//     background = half_width × the largest cell side (3 voxels by default), and inactive space
//     carries ±background by the sign of the field (signed flood fill), so inside is negative.
//   - values in world units (the SDF's own).
// A pruned discretization stores conservative far-field constants in far-field cells; those
// that fall inside the band keep the right sign but a magnitude below the distance (see
// discretize.hpp). A far-field cell's centre lies more than C·R from the surface (C = 2 by
// default, R the half-diagonal), so only part of the band can be affected.
//
// Thread-safety: may be called from any thread (OpenVDB is initialized once, thread-safely).
// Errors: IoError if the file cannot be written (no partial file is left);
// std::invalid_argument if values.size() != n³.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "scene.hpp"

namespace sdfprune {

struct VdbStats {
    uint64_t active_voxels = 0;  // samples inside the narrow band
    float background = 0;        // world units
    vec3 voxel_size;             // the cell size per axis
};

// `values`: n³ samples in [z][y][x] order at the cell centres of the n³ grid over `aabb`.
VdbStats write_vdb_level_set(const std::string& path, const Aabb& aabb, uint32_t n,
                             std::span<const float> values, float half_width = 3.0f);

// What a .vdb file's first float grid holds, read back through OpenVDB (for tests and tools that
// check an output without linking OpenVDB themselves).
struct VdbGridInfo {
    std::string name;
    bool level_set = false;  // grid class GRID_LEVEL_SET
    bool linear = false;     // the transform is linear (scale and translation)
    vec3 voxel_size;         // world size of a voxel per axis
    vec3 origin;             // world position of voxel (0, 0, 0)'s centre
    float background = 0;
    uint64_t active_voxels = 0;
    std::vector<float> probes;          // the grid's value at each requested index coordinate
    std::vector<uint8_t> probe_active;  // whether that voxel is active
};
// Throws IoError if the file cannot be read or holds no float grid.
VdbGridInfo inspect_vdb(const std::string& path,
                        std::span<const std::array<int32_t, 3>> probes = {});

}  // namespace sdfprune

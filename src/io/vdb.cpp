// vdb.cpp — an n³ discretization as an OpenVDB narrow-band level set (see vdb.hpp), written
// through a temporary file so a failure leaves nothing behind.
#include "sdfprune/vdb.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <stdexcept>

#include "sdfprune/io.hpp"

namespace sdfprune {
namespace {

void initialize_openvdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

}  // namespace

VdbStats write_vdb_level_set(const std::string& path, const Aabb& aabb, uint32_t n,
                             std::span<const float> values, float half_width) {
    const uint64_t N = n;
    if (n == 0 || values.size() != N * N * N)
        throw std::invalid_argument("write_vdb_level_set: values must hold n³ samples");
    if (!(half_width > 0)) throw std::invalid_argument("write_vdb_level_set: half_width <= 0");
    initialize_openvdb();

    VdbStats st;
    // The same cell size as discretize.hpp and PrunedGrid (extent / n per axis).
    st.voxel_size = (aabb.max - aabb.min) / float(n);
    const vec3 vs = st.voxel_size;
    const float largest = std::max({vs.x, vs.y, vs.z});
    const float smallest = std::min({vs.x, vs.y, vs.z});
    st.background = half_width * largest;

    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(st.background);
    openvdb::math::Transform::Ptr xf;
    if (largest - smallest <= 1e-6f * largest) {
        xf = openvdb::math::Transform::createLinearTransform(double(vs.x));
    } else {
        // Box cells: a per-axis scale keeps every sample at its own cell centre (vdb.hpp).
        xf = openvdb::math::Transform::createLinearTransform(1.0);
        xf->postScale(openvdb::Vec3d(vs.x, vs.y, vs.z));
    }
    const vec3 first = aabb.min + vs * 0.5f;  // centre of cell (0, 0, 0)
    xf->postTranslate(openvdb::Vec3d(first.x, first.y, first.z));
    grid->setTransform(xf);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("surface");
    grid->insertMeta("creator", openvdb::StringMetadata("sdfprune"));

    {
        openvdb::FloatGrid::Accessor acc = grid->getAccessor();
        const float bg = st.background;
        for (uint32_t z = 0; z < n; ++z)
            for (uint32_t y = 0; y < n; ++y) {
                const float* row = values.data() + (uint64_t(z) * N + y) * N;
                for (uint32_t x = 0; x < n; ++x) {
                    const float v = row[x];
                    if (!(std::fabs(v) < bg)) continue;  // also drops NaN
                    acc.setValue(openvdb::Coord(int(x), int(y), int(z)), v);
                    ++st.active_voxels;
                }
            }
    }
    // Inactive voxels and tiles take -background inside, +background outside.
    openvdb::tools::signedFloodFill(grid->tree());

    write_atomic_with(path, [&](const std::string& tmp) {
        try {
            openvdb::io::File file(tmp);
            openvdb::GridPtrVec grids{grid};
            file.write(grids);
            file.close();
        } catch (const openvdb::Exception& e) {
            throw IoError(path + ": cannot write VDB: " + e.what());
        }
    });
    return st;
}

VdbGridInfo inspect_vdb(const std::string& path, std::span<const std::array<int32_t, 3>> probes) {
    initialize_openvdb();
    VdbGridInfo info;
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open(false);
        grids = file.getGrids();
        file.close();
    } catch (const openvdb::Exception& e) {
        throw IoError(path + ": cannot read VDB: " + e.what());
    }
    openvdb::FloatGrid::Ptr grid;
    for (const openvdb::GridBase::Ptr& g : *grids)
        if ((grid = openvdb::gridPtrCast<openvdb::FloatGrid>(g))) break;
    if (!grid) throw IoError(path + ": no float grid in the file");
    info.name = grid->getName();
    info.level_set = grid->getGridClass() == openvdb::GRID_LEVEL_SET;
    const openvdb::math::Transform& xf = grid->transform();
    info.linear = xf.isLinear();
    const openvdb::Vec3d vs = xf.voxelSize(), o = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
    info.voxel_size = vec3(float(vs.x()), float(vs.y()), float(vs.z()));
    info.origin = vec3(float(o.x()), float(o.y()), float(o.z()));
    info.background = grid->background();
    info.active_voxels = grid->activeVoxelCount();
    openvdb::FloatGrid::ConstAccessor acc = grid->getConstAccessor();
    for (const std::array<int32_t, 3>& c : probes) {
        const openvdb::Coord xyz(c[0], c[1], c[2]);
        info.probes.push_back(acc.getValue(xyz));
        info.probe_active.push_back(acc.isValueOn(xyz) ? 1 : 0);
    }
    return info;
}

}  // namespace sdfprune

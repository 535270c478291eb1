// mesh_io.cpp — mesh writers: binary STL, binary little-endian PLY, Wavefront OBJ. The bytes
// are built in memory and written atomically (io.hpp), so a failed write leaves no file.
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>

#include "sdfprune/io.hpp"
#include "sdfprune/mesh.hpp"

namespace sdfprune {
namespace {

void put_u32(std::string& out, uint32_t v) {
    const char b[4] = {char(v & 0xff), char((v >> 8) & 0xff), char((v >> 16) & 0xff),
                       char((v >> 24) & 0xff)};
    out.append(b, 4);
}
void put_f32(std::string& out, float v) {
    put_u32(out, std::bit_cast<uint32_t>(v));
}
void put_vec3(std::string& out, vec3 v) {
    put_f32(out, v.x);
    put_f32(out, v.y);
    put_f32(out, v.z);
}

// The shortest decimal that reads back to the same float.
void put_float_text(std::string& out, float v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
}
void put_uint_text(std::string& out, uint64_t v) {
    char buf[24];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
}

std::string encode_stl(const Mesh& m) {
    const size_t tris = m.triangle_count();
    if (tris > 0xffffffffull) throw std::length_error("STL holds at most 2^32-1 triangles");
    std::string out;
    out.reserve(84 + tris * 50);
    // The header must not start with "solid", which marks ASCII STL to many readers.
    char header[80] = {};
    std::strncpy(header, "binary STL written by sdfprune", sizeof header);
    out.append(header, sizeof header);
    put_u32(out, uint32_t(tris));
    for (size_t t = 0; t < tris; ++t) {
        const vec3 a = m.vertices[m.triangles[3 * t]], b = m.vertices[m.triangles[3 * t + 1]],
                   c = m.vertices[m.triangles[3 * t + 2]];
        // The unit normal, in double so tiny triangles still get one.
        const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
        const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
        double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
        const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
        if (len > 0) {
            nx /= len;
            ny /= len;
            nz /= len;
        }
        put_vec3(out, vec3(float(nx), float(ny), float(nz)));
        put_vec3(out, a);
        put_vec3(out, b);
        put_vec3(out, c);
        out.append(2, '\0');
    }
    return out;
}

std::string encode_ply(const Mesh& m) {
    if (m.vertices.size() > 0x7fffffffull)
        throw std::length_error("PLY (int indices) holds at most 2^31-1 vertices");
    std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by sdfprune\n";
    out += "element vertex " + std::to_string(m.vertices.size()) + "\n";
    out += "property float x\nproperty float y\nproperty float z\n";
    out += "element face " + std::to_string(m.triangle_count()) + "\n";
    out += "property list uchar int vertex_indices\nend_header\n";
    out.reserve(out.size() + m.vertices.size() * 12 + m.triangle_count() * 13);
    for (const vec3& v : m.vertices) put_vec3(out, v);
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        out.push_back(char(3));
        for (int k = 0; k < 3; ++k) put_u32(out, m.triangles[3 * t + k]);
    }
    return out;
}

std::string encode_obj(const Mesh& m) {
    if (m.vertices.size() > 0x7fffffffull)
        throw std::length_error("OBJ output holds at most 2^31-1 vertices");
    std::string out = "# written by sdfprune: " + std::to_string(m.vertices.size()) +
                      " vertices, " + std::to_string(m.triangle_count()) + " triangles\n";
    out.reserve(out.size() + m.vertices.size() * 32 + m.triangle_count() * 24);
    for (const vec3& v : m.vertices) {
        out += "v ";
        put_float_text(out, v.x);
        out += ' ';
        put_float_text(out, v.y);
        out += ' ';
        put_float_text(out, v.z);
        out += '\n';
    }
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        out += 'f';
        for (int k = 0; k < 3; ++k) {
            out += ' ';
            put_uint_text(out, uint64_t(m.triangles[3 * t + k]) + 1);
        }
        out += '\n';
    }
    return out;
}

}  // namespace

MeshFormat mesh_format_of(const std::string& path) {
    const std::string ext = extension_of(path);
    if (ext == ".stl") return MeshFormat::kStl;
    if (ext == ".ply") return MeshFormat::kPly;
    if (ext == ".obj") return MeshFormat::kObj;
    throw IoError(path + ": unknown mesh extension \"" + ext + "\" (expected .stl, .ply, .obj)");
}

std::string encode_mesh(const Mesh& mesh, MeshFormat format) {
    switch (format) {
        case MeshFormat::kStl:
            return encode_stl(mesh);
        case MeshFormat::kPly:
            return encode_ply(mesh);
        case MeshFormat::kObj:
            return encode_obj(mesh);
    }
    throw std::invalid_argument("unknown mesh format");
}

void write_mesh(const Mesh& mesh, const std::string& path) {
    const MeshFormat format = mesh_format_of(path);
    check_writable(path);
    write_file_atomic(path, encode_mesh(mesh, format));
}

}  // namespace sdfprune

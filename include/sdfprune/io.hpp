// io.hpp — the reference scene format (JSON; ../shared/scenes/README.md and README.md here) and
// safe file output.
//
// Loading is a non-recursive SAX parse (RapidJSON's iterative parser), so files nested millions
// of levels deep load in bounded stack; nesting beyond kMaxJsonDepth is refused. Every error is a
// SceneError whose one-line message names the file and the offending node as a JSON pointer,
// e.g. "scene.json: /leftChild/rightChild: radius must be > 0 (got -1)".
#pragma once

#include <functional>
#include <string>
#include <string_view>

#include "scene.hpp"

namespace sdfprune {

inline constexpr uint32_t kMaxJsonDepth = 1u << 22;

// Reads and validates a scene file. `name` (used in messages) defaults to the path.
Scene load_scene(const std::string& path);
Scene parse_scene(std::string_view json, const std::string& name);

// Writes the scene in the reference format: node matrices as loaded, compact JSON, numbers
// printed as the shortest decimal that reads back to the same float, so load -> save -> load
// gives the same scene. Extension primitives (capsule, torus, rounded_cylinder, capped_cone,
// hex_prism, octahedron, plane: the table of primitives.hpp) are documented in README.md.
std::string scene_to_json(const Scene& scene);
void save_scene(const Scene& scene, const std::string& path);

// Writes `bytes` to `path` atomically: a temporary file beside it, then a rename. Throws
// IoError on failure, leaving no partial file.
struct IoError : std::runtime_error {
    using std::runtime_error::runtime_error;
};
void write_file_atomic(const std::string& path, std::string_view bytes);
// Throws IoError if a file cannot be created at `path` (its directory is missing or not
// writable); creates nothing. For refusing bad output paths before long work.
void check_writable(const std::string& path);
std::string read_file(const std::string& path);
// For writers that need a path (libraries that open files themselves): calls write(tmp) with a
// temporary path beside `path`, then renames it over `path`; on any exception removes the
// temporary file and rethrows. Checks that `path` is writable first.
void write_atomic_with(const std::string& path,
                       const std::function<void(const std::string&)>& write);
// The lower-case extension of a path including the dot (".png"), or "" if none.
std::string extension_of(const std::string& path);

}  // namespace sdfprune

// view_session.hpp — the state behind `sdfprune view` (src/view/view_server.hpp serves it): the
// scene file being viewed, its pruned grids per resolution, frames rendered from them, picking,
// edits re-pruned incrementally (update() in prune.hpp), undo and redo, saving, and reloading
// when the file changes on disk. A layer on the public API; no HTTP here.
//
// Thread-safety: every member function may be called from any thread at any time. A request
// works on an immutable snapshot (scene + grids + version), so frames rendered during an edit
// or a reload show one version or the other, never a mix.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/render.hpp"

namespace sdfprune::view {

// A request the caller can fix (bad numbers, unknown primitive, a scene the edit makes
// invalid): the server answers 400 with the message.
struct BadRequest : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

struct SessionOptions {
    std::string backend = "cpu";  // or "vulkan"
    PruneOptions prune;           // resolution = the default grid; coarse_tapes is set
};

// One frame: the camera as the CLI's render takes it (orbit_camera), the size, the view.
struct FrameRequest {
    uint32_t width = 960, height = 540;
    float yaw = 30, pitch = 25;
    float distance = 0;  // <= 0: frames the AABB
    float fov = 40;
    bool has_target = false;
    vec3 target;  // default: the AABB's centre
    Shading shading = Shading::kShaded;
    bool shadows = true;
    uint32_t grid = 0;   // 0: the session's default resolution
    bool naive = false;  // the full tree at every step (the paper's baseline)
    int64_t highlight = -1;
};

struct Frame {
    Image image;
    RenderStats render;
    PruneStats prune;  // of the grid it was traced on (zeros for naive frames)
    uint64_t version = 0;
    float distance = 0;  // the camera distance used (resolved when the request said auto)
    vec3 target;
};

// The editable numbers of a primitive, by name: its table fields ("radius", "sides.x", ...),
// "translate.x|y|z" (the world point its frame's origin sits at), "color.r|g|b", and
// "blend_radius" (its parent operator's, when it has one).
struct PrimitiveFields {
    uint32_t primitive = 0;
    uint32_t node = 0;
    std::string kind;
    std::vector<std::pair<std::string, float>> fields;
};

class Session {
  public:
    // Loads the scene; throws SceneError / IoError when it cannot (the server is not started).
    Session(std::string path, SessionOptions options);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;

    const std::string& path() const { return path_; }
    const SessionOptions& options() const { return options_; }

    Frame render(const FrameRequest& request);
    // The primitive under pixel (x, y) of the frame `request` describes; false when the ray
    // misses the surface.
    bool pick(const FrameRequest& request, uint32_t x, uint32_t y, PrimitiveFields& out);
    PrimitiveFields fields(uint32_t primitive);
    // Sets some of a primitive's fields (names as in PrimitiveFields); the scene is rebuilt
    // through the loader's validation and the grids re-pruned incrementally. Returns the new
    // version. Throws BadRequest.
    uint64_t edit(uint32_t primitive, const std::vector<std::pair<std::string, float>>& values);
    uint64_t undo();  // BadRequest when there is nothing to undo
    uint64_t redo();
    // Writes the scene atomically to the file it came from.
    void save();
    // Reloads the file if it changed on disk since the last load or save (the watcher calls
    // this); a file that fails to load leaves the scene as it was and sets error().
    void poll_file();

    // A consistent view of the state for the scene endpoint.
    struct Summary {
        uint64_t version = 0;
        std::string error;  // the last reload's failure, "" when the file loaded
        uint32_t nodes = 0, primitives = 0;
        Aabb aabb;
        bool can_undo = false, can_redo = false;
        uint32_t grid = 0;          // default resolution
        bool have_stats = false;    // the default grid has been pruned
        PruneStats prune;           // of the default grid
        double last_update_ms = 0;  // the last edit's incremental re-pruning
    };
    Summary summary();

  private:
    struct State;
    struct GridSlot;
    std::shared_ptr<const State> snapshot() const;
    std::shared_ptr<GridSlot> grid_for(const std::shared_ptr<const State>& s, uint32_t res);
    void commit(std::shared_ptr<const Scene> scene, bool record_undo, bool clear_redo);
    void remember_file();

    std::string path_;
    SessionOptions options_;
    mutable std::mutex state_mutex_;  // guards state_, undo_, redo_, error_, file stamp
    std::mutex edit_mutex_;           // one edit, undo, redo, save or reload at a time
    std::shared_ptr<const State> state_;
    std::vector<std::shared_ptr<const Scene>> undo_, redo_;
    std::string error_;
    // Per resolution, the grid of an earlier version, updated in place by the next edit once no
    // request holds it (no copy of the grid per edit). Guarded by edit_mutex_.
    std::map<uint32_t, std::shared_ptr<PrunedGrid>> spares_;
    int64_t file_mtime_ns_ = 0;
    int64_t file_size_ = -1;
    double last_update_ms_ = 0;
    std::unique_ptr<gpu::Device> device_;  // the Vulkan backend's device
    std::mutex device_mutex_;              // the device runs one command at a time
};

}  // namespace sdfprune::view

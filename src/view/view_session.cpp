// view_session.cpp — the viewer's state (view_session.hpp): snapshots of scene + grids, frames,
// picking, edits through the loader and incremental re-pruning, undo/redo, save and reload.
#include "view_session.hpp"

#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <cstring>

#include "../core/clock.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/primitives.hpp"

namespace sdfprune::view {

// One pruned grid of a snapshot, built on first use.
struct Session::GridSlot {
    std::mutex build;
    std::shared_ptr<PrunedGrid> cpu;
    std::unique_ptr<gpu::Grid> gpu;
};

struct Session::State {
    uint64_t version = 0;
    std::shared_ptr<const Scene> scene;
    mutable std::mutex slots_mutex;
    mutable std::map<uint32_t, std::shared_ptr<GridSlot>> slots;
};

namespace {

// The world point that primitive p's local frame origin sits at.
vec3 primitive_position(const Scene& sc, uint32_t p) {
    const math::PrimitiveParams& prm = sc.params[p];
    Affine a;
    const vec4 rows[3] = {prm.row0, prm.row1, prm.row2};
    for (int i = 0; i < 3; ++i) {
        a.m[4 * i] = rows[i].x;
        a.m[4 * i + 1] = rows[i].y;
        a.m[4 * i + 2] = rows[i].z;
        a.m[4 * i + 3] = rows[i].w;
    }
    const Affine inv = a.inverse();
    return vec3(inv.m[3], inv.m[7], inv.m[11]);
}

const char* kAxes[4] = {"x", "y", "z", "w"};
const char* kChannels[3] = {"r", "g", "b"};

}  // namespace

Session::Session(std::string path, SessionOptions options)
    : path_(std::move(path)), options_(std::move(options)) {
    options_.prune.coarse_tapes = true;
    if (options_.backend != "cpu" && options_.backend != "vulkan")
        throw BadRequest("--backend must be cpu or vulkan (got \"" + options_.backend + "\")");
    if (options_.backend == "vulkan") device_ = std::make_unique<gpu::Device>();
    auto scene = std::make_shared<const Scene>(load_scene(path_));
    remember_file();
    auto s = std::make_shared<State>();
    s->version = 1;
    s->scene = std::move(scene);
    state_ = std::move(s);
}

Session::~Session() = default;

std::shared_ptr<const Session::State> Session::snapshot() const {
    std::lock_guard lock(state_mutex_);
    return state_;
}

std::shared_ptr<Session::GridSlot> Session::grid_for(const std::shared_ptr<const State>& s,
                                                     uint32_t res) {
    std::shared_ptr<GridSlot> slot;
    {
        std::lock_guard lock(s->slots_mutex);
        std::shared_ptr<GridSlot>& at = s->slots[res];
        if (!at) at = std::make_shared<GridSlot>();
        slot = at;
    }
    std::lock_guard build(slot->build);
    PruneOptions o = options_.prune;
    o.resolution = res;
    if (!slot->cpu) slot->cpu = std::make_shared<PrunedGrid>(prune(s->scene, o));
    if (device_ && !slot->gpu) {
        std::lock_guard device(device_mutex_);
        slot->gpu = std::make_unique<gpu::Grid>(gpu::prune(*device_, *s->scene, o));
    }
    return slot;
}

Frame Session::render(const FrameRequest& r) {
    const std::shared_ptr<const State> s = snapshot();
    const Scene& sc = *s->scene;
    if (r.highlight >= int64_t(sc.primitive_count()))
        throw BadRequest("highlight: no primitive " + std::to_string(r.highlight));
    RenderOptions ro;
    ro.width = r.width;
    ro.height = r.height;
    ro.camera = orbit_camera(sc.aabb, r.yaw, r.pitch, r.distance, r.fov,
                             r.has_target ? &r.target : nullptr);
    ro.shading = r.shading;
    ro.shadows = r.shadows;
    ro.highlight_primitive = r.highlight;
    Frame f;
    f.version = s->version;
    f.distance = orbit_distance(sc.aabb, r.distance, r.fov);
    f.target = ro.camera.target;
    if (r.naive) {
        f.image = render_naive(sc, ro, &f.render);
        return f;
    }
    const std::shared_ptr<GridSlot> slot = grid_for(s, r.grid ? r.grid : options_.prune.resolution);
    if (slot->gpu) {
        std::lock_guard device(device_mutex_);
        f.image = gpu::render(*device_, *slot->gpu, ro, &f.render);
        f.prune = slot->gpu->stats();
    } else {
        const std::shared_ptr<const PrunedGrid> grid = slot->cpu;
        f.image = sdfprune::render(*grid, ro, &f.render);
        f.prune = grid->stats();
    }
    return f;
}

PrimitiveFields Session::fields(uint32_t p) {
    const std::shared_ptr<const State> s = snapshot();
    const Scene& sc = *s->scene;
    if (p >= sc.primitive_count()) throw BadRequest("no primitive " + std::to_string(p));
    PrimitiveFields out;
    out.primitive = p;
    out.node = sc.primitive_node[p];
    const PrimitiveKindInfo& info = primitive_info(sc.kind[out.node]);
    out.kind = info.name;
    for (uint32_t i = 0; i < info.field_count; ++i) {
        const PrimitiveField& f = info.fields[i];
        const float* v =
            reinterpret_cast<const float*>(reinterpret_cast<const char*>(&sc.shape[p]) + f.offset);
        for (uint32_t c = 0; c < f.count; ++c)
            out.fields.push_back(
                {f.count == 1 ? std::string(f.name) : std::string(f.name) + "." + kAxes[c], v[c]});
    }
    const vec3 at = primitive_position(sc, p);
    for (int c = 0; c < 3; ++c) out.fields.push_back({std::string("translate.") + kAxes[c], at[c]});
    for (int c = 0; c < 3; ++c)
        out.fields.push_back({std::string("color.") + kChannels[c], sc.color[p][c]});
    const uint32_t parent = sc.parent[out.node];
    if (parent != kNone && sc.blend[parent] > 0)
        out.fields.push_back({"blend_radius", sc.blend[parent]});
    return out;
}

bool Session::pick(const FrameRequest& r, uint32_t x, uint32_t y, PrimitiveFields& out) {
    const std::shared_ptr<const State> s = snapshot();
    const Scene& sc = *s->scene;
    if (x >= r.width || y >= r.height) throw BadRequest("pick: the pixel lies outside the frame");
    RenderOptions ro;
    ro.width = r.width;
    ro.height = r.height;
    ro.camera = orbit_camera(sc.aabb, r.yaw, r.pitch, r.distance, r.fov,
                             r.has_target ? &r.target : nullptr);
    const std::shared_ptr<GridSlot> slot = grid_for(s, r.grid ? r.grid : options_.prune.resolution);
    const std::shared_ptr<const PrunedGrid> grid = slot->cpu;
    const PickResult hit = sdfprune::pick(*grid, ro, x, y);
    if (!hit.hit) return false;
    out = fields(hit.primitive);
    return true;
}

uint64_t Session::edit(uint32_t p, const std::vector<std::pair<std::string, float>>& values) {
    std::lock_guard edits(edit_mutex_);
    const std::shared_ptr<const State> s = snapshot();
    const Scene& cur = *s->scene;
    if (p >= cur.primitive_count()) throw BadRequest("no primitive " + std::to_string(p));
    if (values.empty()) throw BadRequest("edit: no field to set");
    Scene next = cur;
    const uint32_t node = cur.primitive_node[p];
    const PrimitiveKindInfo& info = primitive_info(cur.kind[node]);
    const vec3 at = primitive_position(cur, p);
    vec3 to = at;
    for (const auto& [name, value] : values) {
        if (!std::isfinite(value)) throw BadRequest(name + ": must be a finite number");
        const size_t dot = name.find('.');
        const std::string base = name.substr(0, dot),
                          part = dot == name.npos ? "" : name.substr(dot + 1);
        const auto axis = [&](uint32_t count, const char* const* names) -> int {
            for (uint32_t c = 0; c < count; ++c)
                if (part == names[c]) return int(c);
            throw BadRequest("unknown field \"" + name + "\"");
        };
        if (base == "translate") {
            to[axis(3, kAxes)] = value;
        } else if (base == "color") {
            next.color[p][axis(3, kChannels)] = value;
        } else if (name == "blend_radius") {
            const uint32_t parent = cur.parent[node];
            if (parent == kNone) throw BadRequest("blend_radius: the primitive has no parent");
            next.blend[parent] = value;
        } else {
            const PrimitiveField* f = nullptr;
            for (uint32_t i = 0; i < info.field_count; ++i)
                if (base == info.fields[i].name) f = &info.fields[i];
            if (!f || (f->count == 1) != part.empty())
                throw BadRequest("unknown field \"" + name + "\" for a " + info.name);
            float* v =
                reinterpret_cast<float*>(reinterpret_cast<char*>(&next.shape[p]) + f->offset);
            v[f->count == 1 ? 0 : axis(f->count, kAxes)] = value;
        }
    }
    if (!(to == at)) next = moved_primitive(next, p, to - at);
    // Through the writer and the loader: the edit is validated as a file would be, and every
    // derived array (baked maps, bounds, Lipschitz bounds) is rebuilt.
    std::shared_ptr<const Scene> edited;
    try {
        edited = std::make_shared<const Scene>(parse_scene(scene_to_json(next), path_));
    } catch (const SceneError& e) {
        throw BadRequest(e.what());
    }
    commit(std::move(edited), true, true);
    return snapshot()->version;
}

// Publishes `scene` as the next version. Grids already pruned for the current version are
// updated incrementally when the tree is the same (an edit, or a file rewritten with the same
// structure), reusing the grid two versions old when no request holds it any more.
void Session::commit(std::shared_ptr<const Scene> scene, bool record_undo, bool clear_redo) {
    const std::shared_ptr<const State> old = snapshot();
    auto next = std::make_shared<State>();
    next->version = old->version + 1;
    next->scene = scene;
    const auto t0 = std::chrono::steady_clock::now();
    bool same_tree = true;
    try {
        scene_edit(*old->scene, *scene);
    } catch (const std::invalid_argument&) {
        same_tree = false;
    }
    if (same_tree) {
        std::map<uint32_t, std::shared_ptr<GridSlot>> slots;
        {
            std::lock_guard lock(old->slots_mutex);
            slots = old->slots;
        }
        for (const auto& [res, slot] : slots) {
            std::shared_ptr<PrunedGrid> from;
            {
                std::lock_guard build(slot->build);
                from = slot->cpu;
            }
            if (!from) continue;
            std::shared_ptr<PrunedGrid> spare = std::move(spares_[res]);
            spares_[res] = from;
            auto fresh = std::make_shared<GridSlot>();
            if (spare && spare.use_count() == 1 && spare->level_count() == from->level_count()) {
                const SceneEdit e = scene_edit(spare->scene(), *scene);
                fresh->cpu = std::make_shared<PrunedGrid>(update(std::move(*spare), scene, e));
            } else {
                fresh->cpu = std::make_shared<PrunedGrid>(
                    update(PrunedGrid(*from), scene, scene_edit(*old->scene, *scene)));
            }
            next->slots[res] = std::move(fresh);
        }
    } else {
        spares_.clear();
    }
    const double update_ms = ms_since(t0);
    std::lock_guard lock(state_mutex_);
    if (record_undo) undo_.push_back(old->scene);
    if (clear_redo) redo_.clear();
    last_update_ms_ = update_ms;
    state_ = std::move(next);
}

uint64_t Session::undo() {
    std::lock_guard edits(edit_mutex_);
    std::shared_ptr<const Scene> to;
    {
        std::lock_guard lock(state_mutex_);
        if (undo_.empty()) throw BadRequest("nothing to undo");
        to = undo_.back();
        undo_.pop_back();
        redo_.push_back(state_->scene);
    }
    commit(std::move(to), false, false);
    return snapshot()->version;
}

uint64_t Session::redo() {
    std::lock_guard edits(edit_mutex_);
    std::shared_ptr<const Scene> to;
    {
        std::lock_guard lock(state_mutex_);
        if (redo_.empty()) throw BadRequest("nothing to redo");
        to = redo_.back();
        redo_.pop_back();
    }
    commit(std::move(to), true, false);
    return snapshot()->version;
}

void Session::save() {
    std::lock_guard edits(edit_mutex_);
    write_file_atomic(path_, scene_to_json(*snapshot()->scene));
    remember_file();
}

// The file's modification time and size now, so that poll_file sees only later changes.
void Session::remember_file() {
    struct stat st;
    std::lock_guard lock(state_mutex_);
    if (::stat(path_.c_str(), &st) != 0) return;
    file_mtime_ns_ = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    file_size_ = int64_t(st.st_size);
}

void Session::poll_file() {
    // Under the edits' lock from the look at the file on: save() writes the file and remembers
    // its new time and size under the same lock, so its own write is never taken for someone
    // else's (which reloaded the saved scene as a new version, between a save and an undo).
    std::lock_guard edits(edit_mutex_);
    struct stat st;
    if (::stat(path_.c_str(), &st) != 0) return;  // being replaced; look again later
    const int64_t mtime = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    {
        std::lock_guard lock(state_mutex_);
        if (mtime == file_mtime_ns_ && int64_t(st.st_size) == file_size_) return;
        file_mtime_ns_ = mtime;
        file_size_ = int64_t(st.st_size);
    }
    try {
        auto scene = std::make_shared<const Scene>(load_scene(path_));
        {
            std::lock_guard lock(state_mutex_);
            error_.clear();
        }
        commit(std::move(scene), true, true);
    } catch (const std::exception& e) {
        std::lock_guard lock(state_mutex_);
        error_ = e.what();
    }
}

Session::Summary Session::summary() {
    Summary out;
    std::shared_ptr<const State> s;
    {
        std::lock_guard lock(state_mutex_);
        s = state_;
        out.error = error_;
        out.can_undo = !undo_.empty();
        out.can_redo = !redo_.empty();
        out.last_update_ms = last_update_ms_;
    }
    out.version = s->version;
    out.nodes = s->scene->size();
    out.primitives = s->scene->primitive_count();
    out.aabb = s->scene->aabb;
    out.grid = options_.prune.resolution;
    std::shared_ptr<GridSlot> slot;
    {
        std::lock_guard lock(s->slots_mutex);
        const auto it = s->slots.find(out.grid);
        if (it != s->slots.end()) slot = it->second;
    }
    if (slot) {
        std::lock_guard build(slot->build);
        if (slot->gpu) {
            out.prune = slot->gpu->stats();
            out.have_stats = true;
        } else if (slot->cpu) {
            out.prune = slot->cpu->stats();
            out.have_stats = true;
        }
    }
    return out;
}

}  // namespace sdfprune::view

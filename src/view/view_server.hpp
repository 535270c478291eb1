// view_server.hpp — the HTTP face of `sdfprune view` (cpp-httplib, Debian's libcpp-httplib-dev):
// the page and its scripts (web/, embedded at build time), and a small JSON/PNG API over a
// view::Session, on 127.0.0.1 only.
//
//   GET  /                      the page (also /view.js, /view.css)
//   GET  /api/scene             version, error, counts, AABB, undo/redo, the default grid's stats
//   GET  /api/frame?QUERY       a PNG frame; figures in X-Sdfprune-* headers
//   POST /api/pick?QUERY&x=&y=  the primitive under a pixel: {"hit", "primitive", "kind", "fields"}
//   GET  /api/primitive?id=N    a primitive's editable fields
//   POST /api/edit              body {"primitive": N, "set": {"radius": 0.2, "translate.x": 1}}
//   POST /api/undo | /api/redo | /api/save
// QUERY: w, h, yaw, pitch, distance (0: auto), fov, target=x,y,z, shading=shaded|normals|heatmap,
// shadows=0|1, grid=N, mode=pruned|naive, highlight=N (-1: none). Bad requests get 400 and a
// JSON {"error": "..."}; the server keeps serving whatever a request holds.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include "view_session.hpp"

namespace httplib {
class Server;
}

namespace sdfprune::view {

class Server {
  public:
    explicit Server(Session& session);
    ~Server();
    // Binds 127.0.0.1:port (0: a free port); returns the port. Throws std::runtime_error.
    int bind(int port);
    // Serves until stop() (from another thread or a signal handler's thread); also polls the
    // scene file every `poll_ms` for changes.
    void run(int poll_ms = 200);
    void stop();

  private:
    void routes();
    Session& session_;
    std::unique_ptr<httplib::Server> http_;
    std::atomic<bool> running_{false};
};

// Parses a frame request from query parameters (throws BadRequest on a bad value).
FrameRequest parse_frame_request(const std::multimap<std::string, std::string>& params);

// The page's files, embedded from web/ at build time: path ("/view.js") -> contents.
struct WebAsset {
    const char* path;
    const char* mime;
    const unsigned char* data;
    size_t size;
};
const WebAsset* find_web_asset(const std::string& path);

}  // namespace sdfprune::view

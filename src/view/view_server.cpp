// view_server.cpp — routes of the viewer's HTTP API (view_server.hpp) over a view::Session.
#include "view_server.hpp"

#include <httplib.h>
#include <rapidjson/document.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "../core/clock.hpp"
#include "sdfprune/io.hpp"

namespace sdfprune::view {
namespace {

// JSON text of a string.
std::string quoted(const std::string& s) {
    std::string out = "\"";
    for (const char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (uint8_t(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", unsigned(uint8_t(c)));
            out += buf;
        } else {
            out += c;
        }
    }
    return out + "\"";
}

std::string number(double v) {
    if (!std::isfinite(v)) return "null";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", v);
    return buf;
}

float parse_float(const std::string& name, const std::string& text) {
    float v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v))
        throw BadRequest(name + ": expected a finite number (got \"" + text + "\")");
    return v;
}

int64_t parse_int(const std::string& name, const std::string& text) {
    int64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size())
        throw BadRequest(name + ": expected an integer (got \"" + text + "\")");
    return v;
}

float in_range(const std::string& name, float v, float lo, float hi) {
    if (v < lo || v > hi)
        throw BadRequest(name + ": must lie in [" + number(lo) + ", " + number(hi) + "]");
    return v;
}

std::string fields_json(const PrimitiveFields& f) {
    std::string out = "{\"primitive\":" + std::to_string(f.primitive);
    out += ",\"node\":" + std::to_string(f.node);
    out += ",\"kind\":" + quoted(f.kind);
    out += ",\"fields\":[";
    for (size_t i = 0; i < f.fields.size(); ++i) {
        if (i) out += ',';
        out += "{\"name\":";
        out += quoted(f.fields[i].first);
        out += ",\"value\":";
        out += number(f.fields[i].second);
        out += '}';
    }
    return out + "]}";
}

void send_json(httplib::Response& res, const std::string& body, int status = 200) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(body, "application/json");
}

void send_error(httplib::Response& res, int status, const std::string& message) {
    send_json(res, "{\"error\":" + quoted(message) + "}", status);
}

// Runs a handler, turning what it throws into an HTTP error: the server never dies on a request.
template <class F>
auto guarded(F f) {
    return [f](const httplib::Request& req, httplib::Response& res) {
        try {
            f(req, res);
        } catch (const BadRequest& e) {
            send_error(res, 400, e.what());
        } catch (const SceneError& e) {
            send_error(res, 400, e.what());
        } catch (const std::invalid_argument& e) {
            send_error(res, 400, e.what());
        } catch (const std::exception& e) {
            send_error(res, 500, e.what());
        }
    };
}

}  // namespace

FrameRequest parse_frame_request(const std::multimap<std::string, std::string>& params) {
    FrameRequest r;
    for (const auto& [key, value] : params) {
        if (key == "w") {
            r.width = uint32_t(in_range(key, float(parse_int(key, value)), 1, 4096));
        } else if (key == "h") {
            r.height = uint32_t(in_range(key, float(parse_int(key, value)), 1, 4096));
        } else if (key == "yaw") {
            r.yaw = parse_float(key, value);
        } else if (key == "pitch") {
            r.pitch = in_range(key, parse_float(key, value), -89, 89);
        } else if (key == "distance") {
            r.distance = in_range(key, parse_float(key, value), 0, 1e6f);
        } else if (key == "fov") {
            r.fov = in_range(key, parse_float(key, value), 1, 170);
        } else if (key == "target") {
            const size_t a = value.find(','), b = a == value.npos ? a : value.find(',', a + 1);
            if (b == value.npos) throw BadRequest("target: expected x,y,z");
            r.target = vec3(parse_float(key, value.substr(0, a)),
                            parse_float(key, value.substr(a + 1, b - a - 1)),
                            parse_float(key, value.substr(b + 1)));
            r.has_target = true;
        } else if (key == "shading") {
            if (value == "shaded")
                r.shading = Shading::kShaded;
            else if (value == "normals")
                r.shading = Shading::kNormals;
            else if (value == "heatmap")
                r.shading = Shading::kHeatmap;
            else
                throw BadRequest("shading: shaded, normals or heatmap (got \"" + value + "\")");
        } else if (key == "shadows") {
            if (value != "0" && value != "1") throw BadRequest("shadows: 0 or 1");
            r.shadows = value == "1";
        } else if (key == "grid") {
            const int64_t g = parse_int(key, value);
            if (g < 8 || g > 1024) throw BadRequest("grid: must lie in [8, 1024]");
            r.grid = uint32_t(g);
        } else if (key == "mode") {
            if (value != "pruned" && value != "naive") throw BadRequest("mode: pruned or naive");
            r.naive = value == "naive";
        } else if (key == "highlight") {
            r.highlight = parse_int(key, value);
            if (r.highlight < -1) throw BadRequest("highlight: a primitive index or -1");
        } else if (key != "x" && key != "y" && key != "t") {
            throw BadRequest("unknown parameter \"" + key + "\"");
        }
    }
    if (uint64_t(r.width) * r.height > 4096ull * 2304)
        throw BadRequest("frame too large: at most 4096x2304 pixels");
    return r;
}

Server::Server(Session& session) : session_(session), http_(std::make_unique<httplib::Server>()) {
    // Frames go out as headers then body on a kept-alive connection: without TCP_NODELAY,
    // Nagle's algorithm holds the body until the client's delayed ACK (tens of ms a frame).
    http_->set_tcp_nodelay(true);
    routes();
}

Server::~Server() {
    stop();
}

int Server::bind(int port) {
    const int bound = port == 0 ? http_->bind_to_any_port("127.0.0.1")
                                : (http_->bind_to_port("127.0.0.1", port) ? port : -1);
    if (bound <= 0)
        throw std::runtime_error("cannot listen on 127.0.0.1:" + std::to_string(port) +
                                 " (in use, or not allowed)");
    return bound;
}

void Server::run(int poll_ms) {
    running_ = true;
    std::thread watcher([this, poll_ms] {
        while (running_) {
            session_.poll_file();
            for (int waited = 0; waited < poll_ms && running_; waited += 20)
                std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    });
    http_->listen_after_bind();
    running_ = false;
    watcher.join();
}

void Server::stop() {
    running_ = false;
    if (http_) http_->stop();
}

void Server::routes() {
    httplib::Server& s = *http_;
    s.set_exception_handler([](const httplib::Request&, httplib::Response& res,
                               std::exception_ptr) { send_error(res, 500, "internal error"); });
    const auto asset = [](const httplib::Request& req, httplib::Response& res) {
        const WebAsset* a = find_web_asset(req.path == "/" ? "/index.html" : req.path);
        if (!a) return send_error(res, 404, "no such page: " + req.path);
        res.set_header("Cache-Control", "no-store");
        res.set_content(reinterpret_cast<const char*>(a->data), a->size, a->mime);
    };
    s.Get("/", asset);
    s.Get("/index.html", asset);
    s.Get("/view.js", asset);
    s.Get("/view.css", asset);

    s.Get("/api/scene", guarded([this](const httplib::Request&, httplib::Response& res) {
              const Session::Summary m = session_.summary();
              std::string j = "{\"version\":" + std::to_string(m.version) +
                              ",\"path\":" + quoted(session_.path()) +
                              ",\"backend\":" + quoted(session_.options().backend) +
                              ",\"error\":" + (m.error.empty() ? "null" : quoted(m.error)) +
                              ",\"nodes\":" + std::to_string(m.nodes) +
                              ",\"primitives\":" + std::to_string(m.primitives) + ",\"aabb\":[" +
                              number(m.aabb.min.x) + "," + number(m.aabb.min.y) + "," +
                              number(m.aabb.min.z) + "," + number(m.aabb.max.x) + "," +
                              number(m.aabb.max.y) + "," + number(m.aabb.max.z) + "]" +
                              ",\"can_undo\":" + (m.can_undo ? "true" : "false") +
                              ",\"can_redo\":" + (m.can_redo ? "true" : "false") +
                              ",\"grid\":" + std::to_string(m.grid) +
                              ",\"last_update_ms\":" + number(m.last_update_ms);
              if (m.have_stats)
                  j += ",\"prune_ms\":" + number(m.prune.prune_ms) +
                       ",\"active_avg\":" + number(m.prune.active_avg) +
                       ",\"near_field_active_avg\":" + number(m.prune.near_field_prims_avg) +
                       ",\"near_field_cells\":" + std::to_string(m.prune.near_field_cells);
              send_json(res, j + "}");
          }));

    s.Get("/api/frame", guarded([this](const httplib::Request& req, httplib::Response& res) {
              const FrameRequest r = parse_frame_request(req.params);
              const auto t0 = std::chrono::steady_clock::now();
              const Frame f = session_.render(r);
              std::vector<uint8_t> png = encode_png(f.image, 1);
              const double total_ms = ms_since(t0);
              res.set_header("Cache-Control", "no-store");
              res.set_header("X-Sdfprune-Version", std::to_string(f.version));
              res.set_header("X-Sdfprune-Trace-Ms", number(f.render.trace_ms));
              res.set_header("X-Sdfprune-Frame-Ms", number(total_ms));
              res.set_header("X-Sdfprune-Evals-Per-Pixel", number(f.render.evals_avg));
              res.set_header("X-Sdfprune-Steps-Per-Pixel", number(f.render.steps_avg));
              res.set_header("X-Sdfprune-Prune-Ms", number(f.prune.prune_ms));
              res.set_header("X-Sdfprune-Active-Avg", number(f.prune.active_avg));
              res.set_header("X-Sdfprune-Near-Active-Avg", number(f.prune.near_field_prims_avg));
              res.set_header("X-Sdfprune-Distance", number(f.distance));
              res.set_header("X-Sdfprune-Target", number(f.target.x) + "," + number(f.target.y) +
                                                      "," + number(f.target.z));
              res.set_header("Access-Control-Expose-Headers", "*");
              res.set_content(std::string(png.begin(), png.end()), "image/png");
          }));

    s.Post("/api/pick", guarded([this](const httplib::Request& req, httplib::Response& res) {
               const FrameRequest r = parse_frame_request(req.params);
               if (!req.has_param("x") || !req.has_param("y"))
                   throw BadRequest("pick: needs x and y");
               const int64_t x = parse_int("x", req.get_param_value("x"));
               const int64_t y = parse_int("y", req.get_param_value("y"));
               if (x < 0 || y < 0) throw BadRequest("pick: the pixel lies outside the frame");
               PrimitiveFields f;
               if (!session_.pick(r, uint32_t(x), uint32_t(y), f))
                   return send_json(res, "{\"hit\":false}");
               send_json(res, "{\"hit\":true,\"selection\":" + fields_json(f) + "}");
           }));

    s.Get("/api/primitive", guarded([this](const httplib::Request& req, httplib::Response& res) {
              if (!req.has_param("id")) throw BadRequest("primitive: needs id");
              const int64_t id = parse_int("id", req.get_param_value("id"));
              if (id < 0 || id > int64_t(UINT32_MAX))
                  throw BadRequest("no primitive " + std::to_string(id));
              send_json(res, fields_json(session_.fields(uint32_t(id))));
          }));

    s.Post("/api/edit", guarded([this](const httplib::Request& req, httplib::Response& res) {
               rapidjson::Document d;
               d.Parse(req.body.c_str(), req.body.size());
               if (d.HasParseError() || !d.IsObject())
                   throw BadRequest("edit: the body must be a JSON object");
               if (!d.HasMember("primitive") || !d["primitive"].IsUint())
                   throw BadRequest("edit: \"primitive\" must be a primitive index");
               if (!d.HasMember("set") || !d["set"].IsObject())
                   throw BadRequest("edit: \"set\" must be an object of field: number");
               std::vector<std::pair<std::string, float>> values;
               for (const auto& m : d["set"].GetObject()) {
                   const std::string name(m.name.GetString(), m.name.GetStringLength());
                   if (!m.value.IsNumber()) throw BadRequest(name + ": must be a number");
                   values.push_back({name, float(m.value.GetDouble())});
               }
               const uint64_t v = session_.edit(d["primitive"].GetUint(), values);
               send_json(res, "{\"version\":" + std::to_string(v) + ",\"update_ms\":" +
                                  number(session_.summary().last_update_ms) + "}");
           }));
    s.Post("/api/undo", guarded([this](const httplib::Request&, httplib::Response& res) {
               send_json(res, "{\"version\":" + std::to_string(session_.undo()) + "}");
           }));
    s.Post("/api/redo", guarded([this](const httplib::Request&, httplib::Response& res) {
               send_json(res, "{\"version\":" + std::to_string(session_.redo()) + "}");
           }));
    s.Post("/api/save", guarded([this](const httplib::Request&, httplib::Response& res) {
               session_.save();
               send_json(res, "{\"saved\":" + quoted(session_.path()) + "}");
           }));
    s.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
        if (res.status == 404 && res.body.empty())
            send_error(res, 404, "no such path: " + req.path);
    });
}

}  // namespace sdfprune::view

// view_server_test.cpp — the viewer's HTTP API (src/view/): a view::Server on a free port of
// 127.0.0.1 in this process, driven by cpp-httplib's client: pages, frames equal to render()'s,
// picking, edits equal to a from-scratch prune, undo/redo, save, the file watched on disk, bad
// requests, concurrent clients.
#include <gtest/gtest.h>
#include <httplib.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>

#include "prune_check.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/render.hpp"
#include "view_server.hpp"

namespace sdfprune {
namespace {

namespace fs = std::filesystem;

// A scene file in a temporary folder, a session and a server on it, and a client.
struct Served {
    fs::path dir, file;
    std::unique_ptr<view::Session> session;
    std::unique_ptr<view::Server> server;
    std::thread thread;
    int port = 0;
    std::unique_ptr<httplib::Client> client;

    explicit Served(const Scene& scene, uint32_t grid = 32) {
        static std::atomic<int> counter{0};
        dir = fs::temp_directory_path() / ("sdfprune_view_test_" + std::to_string(::getpid()) +
                                           "_" + std::to_string(counter++));
        fs::create_directories(dir);
        file = dir / "scene.json";
        save_scene(scene, file.string());
        view::SessionOptions o;
        o.prune.resolution = grid;
        session = std::make_unique<view::Session>(file.string(), o);
        server = std::make_unique<view::Server>(*session);
        port = server->bind(0);
        thread = std::thread([this] { server->run(50); });
        client = std::make_unique<httplib::Client>("127.0.0.1", port);
        client->set_read_timeout(60, 0);
        // The server listens once run() has started.
        for (int i = 0; i < 200 && !client->Get("/api/scene"); ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ~Served() {
        server->stop();
        thread.join();
        std::error_code ec;
        fs::remove_all(dir, ec);
    }
    uint64_t version() {
        const auto r = client->Get("/api/scene");
        EXPECT_TRUE(r && r->status == 200);
        const size_t at = r->body.find("\"version\":");
        return std::stoull(r->body.substr(at + 10));
    }
};

Scene small_scene(uint64_t seed) {
    test::RandomSceneSpec spec;
    spec.primitives = 8;
    return test::random_scene(seed, spec);
}

// render() of a grid pruned like the server's, PNG-encoded like its frames.
std::string expected_frame(const Scene& sc, uint32_t grid, const RenderOptions& base) {
    PruneOptions o;
    o.resolution = grid;
    const PrunedGrid g = prune(sc, o);
    const std::vector<uint8_t> png = encode_png(render(g, base), 1);
    return std::string(png.begin(), png.end());
}

RenderOptions frame_options(const Scene& sc, uint32_t w, uint32_t h, float yaw, float pitch,
                            Shading shading) {
    RenderOptions ro;
    ro.width = w;
    ro.height = h;
    ro.camera = orbit_camera(sc.aabb, yaw, pitch, 0, 40);
    ro.shading = shading;
    return ro;
}

TEST(ViewServer, ServesThePageAndItsScripts) {
    Served s(small_scene(1));
    const auto page = s.client->Get("/");
    ASSERT_TRUE(page);
    EXPECT_EQ(page->status, 200);
    EXPECT_NE(page->body.find("sdfprune view"), std::string::npos);
    EXPECT_NE(page->get_header_value("Content-Type").find("text/html"), std::string::npos);
    for (const char* path : {"/view.js", "/view.css"}) {
        const auto r = s.client->Get(path);
        ASSERT_TRUE(r) << path;
        EXPECT_EQ(r->status, 200) << path;
        EXPECT_GT(r->body.size(), 100u) << path;
    }
    const auto missing = s.client->Get("/nothing-here");
    ASSERT_TRUE(missing);
    EXPECT_EQ(missing->status, 404);
    EXPECT_NE(missing->body.find("\"error\""), std::string::npos);
}

TEST(ViewServer, FramesAreTheRendersOfThePrunedGrid) {
    const Scene sc = small_scene(2);
    Served s(sc);
    const auto r = s.client->Get("/api/frame?w=64&h=40&yaw=10&pitch=20&shading=normals");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
    EXPECT_EQ(r->get_header_value("X-Sdfprune-Version"), "1");
    EXPECT_EQ(r->body,
              expected_frame(sc, 32, frame_options(sc, 64, 40, 10, 20, Shading::kNormals)));
    // Another camera, another picture; the naive method draws the same surface.
    const auto other = s.client->Get("/api/frame?w=64&h=40&yaw=100&pitch=20&shading=normals");
    ASSERT_TRUE(other);
    EXPECT_NE(other->body, r->body);
    const auto naive = s.client->Get("/api/frame?w=64&h=40&yaw=10&pitch=20&mode=naive");
    ASSERT_TRUE(naive);
    EXPECT_EQ(naive->status, 200);
}

TEST(ViewServer, ReportsTheScene) {
    const Scene sc = small_scene(3);
    Served s(sc);
    const auto r = s.client->Get("/api/scene");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_NE(r->body.find("\"nodes\":" + std::to_string(sc.size())), std::string::npos);
    EXPECT_NE(r->body.find("\"error\":null"), std::string::npos);
    EXPECT_EQ(s.version(), 1u);
}

// Selects the primitive at the frame's centre, edits it, and checks the frame against a fresh
// prune of the saved scene; then undo, redo and the file on disk.
TEST(ViewServer, PickEditUndoRedoSave) {
    const Scene sc = small_scene(4);
    Served s(sc);
    const std::string q = "w=64&h=40&yaw=20&pitch=15";
    // The first pixel, from the centre outwards, whose ray hits the surface.
    std::string picked;
    for (int r = 0; r < 20 && picked.find("\"hit\":true") == std::string::npos; ++r) {
        const int x = 32 + (r % 2 ? r : -r), y = 20 + (r / 2 % 2 ? r / 2 : -r / 2);
        const auto res =
            s.client->Post("/api/pick?" + q + "&x=" + std::to_string(x) + "&y=" + std::to_string(y),
                           "", "text/plain");
        ASSERT_TRUE(res);
        ASSERT_EQ(res->status, 200) << res->body;
        picked = res->body;
    }
    ASSERT_NE(picked.find("\"hit\":true"), std::string::npos) << picked;
    const size_t at = picked.find("\"primitive\":");
    const uint32_t prim = uint32_t(std::stoul(picked.substr(at + 12)));
    ASSERT_LT(prim, sc.primitive_count());
    const auto before = s.client->Get("/api/frame?" + q);
    ASSERT_TRUE(before);

    const std::string body = "{\"primitive\":" + std::to_string(prim) +
                             ",\"set\":{\"translate.x\":0.3,\"color.g\":0.5}}";
    const auto edited = s.client->Post("/api/edit", body, "application/json");
    ASSERT_TRUE(edited);
    ASSERT_EQ(edited->status, 200) << edited->body;
    EXPECT_EQ(s.version(), 2u);
    const auto after = s.client->Get("/api/frame?" + q);
    ASSERT_TRUE(after);
    EXPECT_NE(after->body, before->body);
    const auto fields = s.client->Get("/api/primitive?id=" + std::to_string(prim));
    ASSERT_TRUE(fields);
    EXPECT_NE(fields->body.find("{\"name\":\"translate.x\",\"value\":0.3"), std::string::npos)
        << fields->body;

    // Saved, the scene loads to what the frame shows: the incremental update equals a full prune.
    const auto saved = s.client->Post("/api/save", "", "text/plain");
    ASSERT_TRUE(saved);
    ASSERT_EQ(saved->status, 200) << saved->body;
    const Scene on_disk = load_scene(s.file.string());
    EXPECT_FLOAT_EQ(on_disk.color[prim].y, 0.5f);
    RenderOptions ro = frame_options(on_disk, 64, 40, 20, 15, Shading::kShaded);
    ro.shadows = true;
    EXPECT_EQ(after->body, expected_frame(on_disk, 32, ro));

    const auto undone = s.client->Post("/api/undo", "", "text/plain");
    ASSERT_TRUE(undone);
    EXPECT_EQ(undone->status, 200);
    const auto back = s.client->Get("/api/frame?" + q);
    ASSERT_TRUE(back);
    EXPECT_EQ(back->body, before->body);
    const auto redone = s.client->Post("/api/redo", "", "text/plain");
    ASSERT_TRUE(redone);
    EXPECT_EQ(redone->status, 200);
    EXPECT_EQ(s.client->Get("/api/frame?" + q)->body, after->body);
    const auto nothing = s.client->Post("/api/redo", "", "text/plain");
    ASSERT_TRUE(nothing);
    EXPECT_EQ(nothing->status, 400);
}

TEST(ViewServer, ReloadsTheFileAndKeepsTheLastGoodScene) {
    Served s(small_scene(5));
    const std::string q = "/api/frame?w=48&h=32";
    const auto first = s.client->Get(q);
    ASSERT_TRUE(first);
    // Another scene written over the file: a new version with a new picture.
    const Scene other = small_scene(6);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    save_scene(other, s.file.string());
    for (int i = 0; i < 200 && s.version() < 2; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    EXPECT_EQ(s.version(), 2u);
    const auto second = s.client->Get(q);
    ASSERT_TRUE(second);
    EXPECT_NE(second->body, first->body);
    // A broken file: the error is reported and the last good scene stays.
    { std::ofstream(s.file) << "{\"nodeType\": \"primitive\", broken"; }
    std::string scene_json;
    for (int i = 0; i < 200; ++i) {
        scene_json = s.client->Get("/api/scene")->body;
        if (scene_json.find("\"error\":null") == std::string::npos) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_NE(scene_json.find("invalid JSON"), std::string::npos) << scene_json;
    EXPECT_EQ(s.version(), 2u);
    const auto still = s.client->Get(q);
    ASSERT_TRUE(still);
    EXPECT_EQ(still->status, 200);
    EXPECT_EQ(still->body, second->body);
}

TEST(ViewServer, BadRequestsGetFourHundredAndTheServerGoesOn) {
    Served s(small_scene(7));
    for (const char* q :
         {"/api/frame?w=0", "/api/frame?w=abc", "/api/frame?w=100000&h=100000",
          "/api/frame?pitch=95", "/api/frame?fov=nan", "/api/frame?yaw=inf",
          "/api/frame?shading=cartoon", "/api/frame?target=1,2", "/api/frame?mode=fast",
          "/api/frame?highlight=99999", "/api/frame?grid=3", "/api/frame?unknown=1",
          "/api/primitive?id=99999", "/api/primitive?id=-1", "/api/primitive"}) {
        const auto r = s.client->Get(q);
        ASSERT_TRUE(r) << q;
        EXPECT_EQ(r->status, 400) << q << ": " << r->body;
        EXPECT_NE(r->body.find("\"error\""), std::string::npos) << q;
    }
    for (const char* body :
         {"", "not json", "[]", "{\"primitive\":0}", "{\"primitive\":-1,\"set\":{}}",
          "{\"primitive\":0,\"set\":{\"radius\":\"big\"}}",
          "{\"primitive\":0,\"set\":{\"no_such_field\":1}}",
          "{\"primitive\":0,\"set\":{\"translate.q\":1}}",
          "{\"primitive\":0,\"set\":{\"color.r\":7}}",
          "{\"primitive\":99999,\"set\":{\"radius\":1}}"}) {
        const auto r = s.client->Post("/api/edit", body, "application/json");
        ASSERT_TRUE(r) << body;
        EXPECT_EQ(r->status, 400) << body << ": " << r->body;
    }
    const auto pick = s.client->Post("/api/pick?w=10&h=10&x=50&y=5", "", "text/plain");
    ASSERT_TRUE(pick);
    EXPECT_EQ(pick->status, 400);
    EXPECT_EQ(s.client->Post("/api/undo", "", "text/plain")->status, 400);
    EXPECT_EQ(s.version(), 1u);
    const auto ok = s.client->Get("/api/frame?w=16&h=16");
    ASSERT_TRUE(ok);
    EXPECT_EQ(ok->status, 200);
}

TEST(ViewServer, ConcurrentClientsAndEdits) {
    const Scene sc = small_scene(8);
    Served s(sc);
    std::atomic<int> failures{0};
    std::vector<std::thread> clients;
    for (int c = 0; c < 4; ++c)
        clients.emplace_back([&, c] {
            httplib::Client client("127.0.0.1", s.port);
            client.set_read_timeout(60, 0);
            for (int i = 0; i < 6; ++i) {
                const auto r = client.Get("/api/frame?w=40&h=30&yaw=" + std::to_string(c * 40 + i));
                if (!r || r->status != 200 || r->body.size() < 8) ++failures;
            }
        });
    clients.emplace_back([&] {
        httplib::Client client("127.0.0.1", s.port);
        client.set_read_timeout(60, 0);
        for (int i = 0; i < 6; ++i) {
            const std::string body =
                "{\"primitive\":0,\"set\":{\"translate.y\":" + std::to_string(0.05 * i) + "}}";
            const auto r = client.Post("/api/edit", body, "application/json");
            if (!r || r->status != 200) ++failures;
        }
    });
    for (std::thread& t : clients) t.join();
    EXPECT_EQ(failures.load(), 0);
    EXPECT_EQ(s.version(), 7u);
}

}  // namespace
}  // namespace sdfprune

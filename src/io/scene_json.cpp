// scene_json.cpp — the reference JSON scene format: a streaming (SAX) loader on RapidJSON's
// iterative parser, with an explicit frame stack instead of recursion, and a writer that walks
// the tree with an explicit stack. Field reference: README.md, "Scene format".
#include <rapidjson/error/en.h>
#include <rapidjson/reader.h>
#include <rapidjson/stringbuffer.h>
#include <rapidjson/writer.h>

#include <algorithm>
#include <charconv>
#include <cmath>

#include "sdfprune/io.hpp"
#include "sdfprune/primitives.hpp"

namespace sdfprune {
namespace {

// The structural fields of a node; the primitives' parameter fields (primitives.hpp) follow
// from kFirstParam on, one per distinct field name of the primitive table.
enum class Field : uint8_t {
    None,
    Unknown,
    NodeType,
    Matrix,
    BlendMode,
    BlendRadius,
    LeftChild,
    RightChild,
    PrimitiveType,
    Color,
    AabbMin,
    AabbMax,
    kFirstParam,
};

struct FieldInfo {
    const char* name;
    Field field;
    char type;      // 's' string, 'n' number, 'a' array of numbers, 'o' object
    uint8_t count;  // arrays: exact number of entries
    const PrimitiveField* param = nullptr;  // parameter fields: where the values go
};

// Every field a node may have: the structural ones, then each primitive field name once.
const std::vector<FieldInfo>& fields() {
    static const std::vector<FieldInfo> all = [] {
        std::vector<FieldInfo> v = {
            {"nodeType", Field::NodeType, 's', 0},
            {"matrix", Field::Matrix, 'a', 12},
            {"blendMode", Field::BlendMode, 's', 0},
            {"blendRadius", Field::BlendRadius, 'n', 0},
            {"leftChild", Field::LeftChild, 'o', 0},
            {"rightChild", Field::RightChild, 'o', 0},
            {"primitiveType", Field::PrimitiveType, 's', 0},
            {"color", Field::Color, 'a', 3},
            {"aabb_min", Field::AabbMin, 'a', 3},
            {"aabb_max", Field::AabbMax, 'a', 3},
        };
        uint32_t next = uint32_t(Field::kFirstParam);
        for (const PrimitiveKindInfo& k : kPrimitiveTable)
            for (uint32_t i = 0; i < k.field_count; ++i) {
                const PrimitiveField& f = k.fields[i];
                const bool known = std::any_of(v.begin(), v.end(), [&](const FieldInfo& x) {
                    return std::string_view(x.name) == f.name;
                });
                if (!known)
                    v.push_back({f.name, Field(next++), f.count == 1 ? 'n' : 'a',
                                 f.count == 1 ? uint8_t(0) : f.count, &f});
            }
        return v;
    }();
    return all;
}

const FieldInfo* field_info(Field f) {
    for (const FieldInfo& i : fields())
        if (i.field == f) return &i;
    return nullptr;
}

Field field_named(std::string_view name) {
    for (const FieldInfo& i : fields())
        if (name == i.name) return i.field;
    return Field::Unknown;
}

// "sphere, box, ..." for messages.
std::string primitive_names() {
    std::string out;
    for (const PrimitiveKindInfo& k : kPrimitiveTable)
        out += (out.empty() ? "" : ", ") + std::string(k.name);
    return out;
}

const char* type_name(char t) {
    switch (t) {
        case 's':
            return "a string";
        case 'n':
            return "a number";
        case 'a':
            return "an array of numbers";
        default:
            return "an object";
    }
}

uint64_t bit(Field f) {
    return uint64_t(1) << uint32_t(f);
}

// One node while it is being read.
struct RawNode {
    SceneNodeDesc desc;
    uint32_t parent = kNone;
    bool is_right = false;
    uint8_t node_type = 0;  // 0 unset, 1 primitive, 2 operator
    uint32_t prim_kind = kNone, op_kind = kNone;
    uint64_t seen = 0;
};

struct Frame {
    enum Kind : uint8_t { Node, Array, Skip } kind;
    Field field = Field::None;  // Node: the key being read; Array: the field being filled
    uint32_t node = kNone;
    uint32_t count = 0;  // Array: entries so far; Skip: nesting depth
};

// Thrown inside the handler and turned into a false return: RapidJSON then stops parsing.
struct ParseFailure {
    std::string message;
};

class SceneHandler {
  public:
    std::vector<RawNode> nodes;
    Aabb aabb;
    std::string error;  // set when a handler call returned false
    size_t depth = 0;

    bool StartObject() {
        return guard([&] { start_object(); });
    }
    bool EndObject(rapidjson::SizeType) {
        return guard([&] { end_object(); });
    }
    bool StartArray() {
        return guard([&] { start_array(); });
    }
    bool EndArray(rapidjson::SizeType) {
        return guard([&] { end_array(); });
    }
    bool Key(const char* s, rapidjson::SizeType n, bool) {
        return guard([&] { key(std::string_view(s, n)); });
    }
    bool String(const char* s, rapidjson::SizeType n, bool) {
        return guard([&] { string(std::string_view(s, n)); });
    }
    // Never called with kParseNumbersAsStringsFlag, but the reader's interface needs them.
    bool Int(int v) {
        return guard([&] { number(v); });
    }
    bool Uint(unsigned v) {
        return guard([&] { number(v); });
    }
    bool Int64(int64_t v) {
        return guard([&] { number(double(v)); });
    }
    bool Uint64(uint64_t v) {
        return guard([&] { number(double(v)); });
    }
    bool Double(double v) {
        return guard([&] { number(v); });
    }
    // Numbers arrive as text (kParseNumbersAsStringsFlag) and are converted by from_chars:
    // correctly rounded like RapidJSON's full-precision path, whose DiyFp code in Debian's
    // RapidJSON 1.1.0 calls clz(0) (undefined) on some inputs (fuzz/regressions/scene_loader).
    bool RawNumber(const char* s, rapidjson::SizeType n, bool) {
        return guard([&] { number(to_double(std::string_view(s, n))); });
    }
    bool Null() {
        return guard([&] { scalar("null"); });
    }
    bool Bool(bool) {
        return guard([&] { scalar("a boolean"); });
    }

    // The JSON pointer of a node, with long runs elided so messages stay one short line.
    std::string node_path(uint32_t node) const {
        std::vector<bool> steps;  // true = rightChild, from the node up
        for (uint32_t n = node; n != kNone && nodes[n].parent != kNone; n = nodes[n].parent)
            steps.push_back(nodes[n].is_right);
        std::string path;
        const size_t total = steps.size();
        for (size_t i = 0; i < total; ++i) {
            if (total > 12 && i == 4) {
                path += "/...(" + std::to_string(total - 10) + " more levels)...";
                i = total - 7;
                continue;
            }
            path += steps[total - 1 - i] ? "/rightChild" : "/leftChild";
        }
        return path.empty() ? "/" : path;
    }

  private:
    std::vector<Frame> frames_;

    template <class F>
    bool guard(F&& f) {
        try {
            f();
            return true;
        } catch (const ParseFailure& e) {
            error = e.message;
            return false;
        }
    }

    [[noreturn]] void fail(const std::string& what) const {
        uint32_t node = kNone;
        Field field = Field::None;
        for (auto it = frames_.rbegin(); it != frames_.rend(); ++it) {
            if (field == Field::None && it->kind != Frame::Skip) field = it->field;
            if (it->kind == Frame::Node) {
                node = it->node;
                field = it->field == Field::None ? field : it->field;
                break;
            }
        }
        std::string where = node == kNone ? "/" : node_path(node);
        const FieldInfo* fi = field_info(field);
        if (fi) where += (where == "/" ? "" : "/") + std::string(fi->name);
        throw ParseFailure{where + ": " + what};
    }

    void enter() {
        if (++depth > kMaxJsonDepth)
            fail("nesting deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    }

    Frame& top() { return frames_.back(); }

    // A JSON number's text (RapidJSON has checked its syntax) as the nearest double; beyond the
    // double range ±infinity or ±0, as strtod gives.
    static double to_double(std::string_view t) {
        double v = 0;
        if (std::from_chars(t.data(), t.data() + t.size(), v).ec == std::errc()) return v;
        long double w = 0;  // out of range: overflow or underflow?
        const bool parsed = std::from_chars(t.data(), t.data() + t.size(), w).ec == std::errc();
        const bool negative = !t.empty() && t[0] == '-';
        const bool tiny =
            parsed ? std::fabs(w) < 1 : t.find("e-") != t.npos || t.find("E-") != t.npos;
        return tiny ? (negative ? -0.0 : 0.0) : (negative ? -HUGE_VAL : HUGE_VAL);
    }

    // The field of the current node awaiting a value of JSON type `type`; nullptr to ignore.
    const FieldInfo* expect(char type, const char* got) {
        Frame& f = top();
        if (f.field == Field::Unknown) return nullptr;
        if (f.field == Field::None) fail("unexpected value");  // cannot happen in valid SAX
        const FieldInfo* fi = field_info(f.field);
        if (fi->type != type) fail("expected " + std::string(type_name(fi->type)) + ", got " + got);
        return fi;
    }

    void start_object() {
        enter();
        if (frames_.empty()) {
            if (!nodes.empty()) fail("more than one top-level value");
            nodes.push_back({});
            frames_.push_back({Frame::Node, Field::None, 0, 0});
            return;
        }
        Frame& f = top();
        if (f.kind == Frame::Skip) {
            ++f.count;
            return;
        }
        if (f.kind == Frame::Array) fail("expected a number, got an object");
        if (!expect('o', "an object")) {
            frames_.push_back({Frame::Skip, Field::None, kNone, 1});
            return;
        }
        if (nodes.size() >= kMaxNodes) fail("too many nodes");
        const uint32_t parent = f.node, child = uint32_t(nodes.size());
        const bool right = f.field == Field::RightChild;
        nodes.push_back({});
        nodes[child].parent = parent;
        nodes[child].is_right = right;
        (right ? nodes[parent].desc.right : nodes[parent].desc.left) = child;
        f.field = Field::None;
        frames_.push_back({Frame::Node, Field::None, child, 0});
    }

    void end_object() {
        --depth;
        Frame& f = top();
        if (f.kind == Frame::Skip) {
            if (--f.count == 0) frames_.pop_back();
            return;
        }
        finish_node(f.node);
        frames_.pop_back();
    }

    void start_array() {
        enter();
        if (frames_.empty()) fail("the top-level value must be an object (a node)");
        Frame& f = top();
        if (f.kind == Frame::Skip) {
            ++f.count;
            return;
        }
        if (f.kind == Frame::Array) fail("expected a number, got an array");
        if (!expect('a', "an array")) {
            frames_.push_back({Frame::Skip, Field::None, kNone, 1});
            return;
        }
        const Frame array{Frame::Array, f.field, f.node, 0};
        f.field = Field::None;  // before push_back, which may move the frames
        frames_.push_back(array);
    }

    void end_array() {
        --depth;
        Frame& f = top();
        if (f.kind == Frame::Skip) {
            if (--f.count == 0) frames_.pop_back();
            return;
        }
        const FieldInfo* fi = field_info(f.field);
        if (f.count != fi->count)
            fail("expected " + std::to_string(fi->count) + " numbers, got " +
                 std::to_string(f.count));
        frames_.pop_back();
    }

    void key(std::string_view name) {
        Frame& f = top();
        if (f.kind == Frame::Skip) return;
        const Field field = field_named(name);
        if (field != Field::Unknown) {
            RawNode& n = nodes[f.node];
            if (n.seen & bit(field)) fail("duplicate field \"" + std::string(name) + "\"");
            n.seen |= bit(field);
        }
        f.field = field;
    }

    void string(std::string_view s) {
        if (frames_.empty()) fail("the top-level value must be an object (a node)");
        Frame& f = top();
        if (f.kind == Frame::Skip) return;
        if (f.kind == Frame::Array) fail("expected a number, got a string");
        const FieldInfo* fi = expect('s', "a string");
        if (fi) {
            RawNode& n = nodes[f.node];
            std::string quoted(1, '"');
            quoted.append(s.substr(0, 64)).push_back('"');
            if (fi->field == Field::NodeType) {
                if (s == "primitive")
                    n.node_type = 1;
                else if (s == "binaryOperator")
                    n.node_type = 2;
                else
                    fail("unknown node type " + quoted + " (primitive, binaryOperator)");
            } else if (fi->field == Field::BlendMode) {
                n.op_kind = operator_kind_from_name(s);
                if (n.op_kind == kNone)
                    fail("unknown blend mode " + quoted + " (union, inter, sub)");
            } else {
                n.prim_kind = primitive_kind_from_name(s);
                if (n.prim_kind == kNone)
                    fail("unknown primitive type " + quoted + " (" + primitive_names() + ")");
            }
        }
        f.field = Field::None;
    }

    void number(double v) {
        if (frames_.empty()) fail("the top-level value must be an object (a node)");
        Frame& f = top();
        if (f.kind == Frame::Skip) return;
        const float x = float(v);
        if (f.kind == Frame::Array) {
            const FieldInfo* fi = field_info(f.field);
            if (f.count >= fi->count)
                fail("expected " + std::to_string(fi->count) + " numbers, got more");
            if (!std::isfinite(x)) fail("numbers must be finite float values");
            store_array(nodes[f.node], f.field, f.count++, x);
            return;
        }
        const FieldInfo* fi = expect('n', "a number");
        if (fi) {
            if (!std::isfinite(x)) fail("numbers must be finite float values");
            if (fi->param)
                field_values(nodes[f.node].desc.shape, *fi->param)[0] = x;
            else
                nodes[f.node].desc.blend = x;
        }
        f.field = Field::None;
    }

    void scalar(const char* got) {
        if (frames_.empty()) fail("the top-level value must be an object (a node)");
        Frame& f = top();
        if (f.kind == Frame::Skip) return;
        if (f.kind == Frame::Array) fail(std::string("expected a number, got ") + got);
        if (f.field != Field::Unknown) expect('-', got);
        f.field = Field::None;
    }

    void store_array(RawNode& n, Field field, uint32_t i, float x) {
        if (const FieldInfo* fi = field_info(field); fi->param) {
            field_values(n.desc.shape, *fi->param)[i] = x;
            return;
        }
        switch (field) {
            case Field::Matrix:
                n.desc.matrix.m[i] = x;
                break;
            case Field::Color:
                n.desc.color[int(i)] = x;
                break;
            case Field::AabbMin:
                aabb.min[int(i)] = x;
                break;
            default:
                aabb.max[int(i)] = x;
                break;
        }
    }

    void require(const RawNode& n, Field field) {
        if (!(n.seen & bit(field)))
            fail("missing field \"" + std::string(field_info(field)->name) + "\"");
    }
    void require(const RawNode& n, const char* name) { require(n, field_named(name)); }

    void finish_node(uint32_t index) {
        RawNode& n = nodes[index];
        top().field = Field::None;
        if (index == 0) {
            require(n, Field::AabbMin);
            require(n, Field::AabbMax);
        }
        require(n, Field::NodeType);
        require(n, Field::Matrix);
        if (n.node_type == 2) {
            for (Field f :
                 {Field::BlendMode, Field::BlendRadius, Field::LeftChild, Field::RightChild})
                require(n, f);
            n.desc.kind = n.op_kind;
        } else {
            require(n, Field::PrimitiveType);
            n.desc.kind = n.prim_kind;
            const PrimitiveKindInfo& info = primitive_info(n.prim_kind);
            for (uint32_t i = 0; i < info.field_count; ++i)
                if (info.fields[i].required) require(n, info.fields[i].name);
        }
        if (std::string e = validate_node(n.desc); !e.empty()) fail(e);
    }
};

}  // namespace

Scene parse_scene(std::string_view json, const std::string& name) {
    SceneHandler h;
    rapidjson::Reader reader;
    // A NUL-terminated copy is not needed: MemoryStream reads exactly the given bytes.
    rapidjson::MemoryStream ms(json.data(), json.size());
    rapidjson::EncodedInputStream<rapidjson::UTF8<>, rapidjson::MemoryStream> is(ms);
    constexpr unsigned kFlags =
        rapidjson::kParseIterativeFlag | rapidjson::kParseNumbersAsStringsFlag;
    rapidjson::ParseResult r = reader.Parse<kFlags>(is, h);
    if (r.IsError()) {
        if (!h.error.empty()) throw SceneError(name + ": " + h.error);
        throw SceneError(name + ": invalid JSON at byte " + std::to_string(r.Offset()) + ": " +
                         rapidjson::GetParseError_En(r.Code()));
    }
    if (h.nodes.empty())
        throw SceneError(name + ": the top-level value must be an object (a node)");
    std::vector<SceneNodeDesc> descs;
    descs.reserve(h.nodes.size());
    for (const RawNode& n : h.nodes) descs.push_back(n.desc);
    try {
        // The root is description 0; build_scene walks from it.
        return build_scene(descs, 0, h.aabb);
    } catch (const SceneNodeError& e) {
        throw SceneError(name + ": " + h.node_path(e.node) + ": " + e.reason);
    } catch (const SceneError& e) {
        throw SceneError(name + ": " + e.what());
    }
}

Scene load_scene(const std::string& path) {
    std::string text;
    try {
        text = read_file(path);
    } catch (const IoError& e) {
        throw SceneError(e.what());
    }
    return parse_scene(text, path);
}

namespace {

using JsonWriter = rapidjson::Writer<rapidjson::StringBuffer>;

void write_float(JsonWriter& w, float x) {
    if (x == 0.0f) x = 0.0f;  // "-0" would read back as an integer 0: write +0 to keep bytes stable
    char buf[32];
    auto res = std::to_chars(buf, buf + sizeof buf, x);
    w.RawValue(buf, size_t(res.ptr - buf), rapidjson::kNumberType);
}

void write_floats(JsonWriter& w, const char* key, const float* v, int n) {
    w.Key(key);
    w.StartArray();
    for (int i = 0; i < n; ++i) write_float(w, v[i]);
    w.EndArray();
}

void write_vec(JsonWriter& w, const char* key, vec3 v) {
    const float a[3] = {v.x, v.y, v.z};
    write_floats(w, key, a, 3);
}

void write_number(JsonWriter& w, const char* key, float x) {
    w.Key(key);
    write_float(w, x);
}

void write_primitive_fields(JsonWriter& w, const Scene& sc, uint32_t node) {
    const uint32_t p = sc.primitive[node];
    const uint32_t kind = sc.kind[node];
    const PrimitiveShape& s = sc.shape[p];
    w.Key("primitiveType");
    w.String(primitive_kind_name(kind));
    const PrimitiveKindInfo& info = primitive_info(kind);
    bool rounding_written = false;
    for (uint32_t i = 0; i < info.field_count; ++i) {
        const PrimitiveField& f = info.fields[i];
        const float* v = field_values(s, f);
        if (f.count == 1)
            write_number(w, f.name, v[0]);
        else
            write_floats(w, f.name, v, f.count);
        rounding_written |= std::string_view(f.name) == "round_x";
    }
    // The reference format gives every primitive round_x and round_y.
    if (!rounding_written) {
        write_number(w, "round_x", s.round_x);
        write_number(w, "round_y", s.round_y);
    }
    write_vec(w, "color", sc.color[p]);
}

}  // namespace

std::string scene_to_json(const Scene& sc) {
    rapidjson::StringBuffer buf;
    JsonWriter w(buf);
    struct Step {
        uint32_t node;
        uint8_t stage;  // 0: open and fields; 1: right child next; 2: close
    };
    std::vector<Step> stack{{sc.root(), 0}};
    while (!stack.empty()) {
        const Step s = stack.back();
        stack.pop_back();
        const uint32_t n = s.node;
        const bool op = !sc.is_primitive(n);
        if (s.stage == 0) {
            w.StartObject();
            if (n == sc.root()) {
                write_vec(w, "aabb_min", sc.aabb.min);
                write_vec(w, "aabb_max", sc.aabb.max);
            }
            w.Key("nodeType");
            w.String(op ? "binaryOperator" : "primitive");
            write_floats(w, "matrix", sc.local[n].m, 12);
            if (!op) {
                write_primitive_fields(w, sc, n);
                w.EndObject();
                continue;
            }
            w.Key("blendMode");
            w.String(operator_kind_name(sc.kind[n]));
            write_number(w, "blendRadius", sc.blend[n]);
            w.Key("leftChild");
            stack.push_back({n, 1});
            stack.push_back({sc.left[n], 0});
        } else if (s.stage == 1) {
            w.Key("rightChild");
            stack.push_back({n, 2});
            stack.push_back({sc.right[n], 0});
        } else {
            w.EndObject();
        }
    }
    return std::string(buf.GetString(), buf.GetSize()) + "\n";
}

void save_scene(const Scene& scene, const std::string& path) {
    write_file_atomic(path, scene_to_json(scene));
}

}  // namespace sdfprune

// gpu_layout_test.cpp — the layouts the kernels and the host share, checked on both sides: the
// member offsets and array strides glslc gave every named struct and block of each kernel
// (read from unoptimized SPIR-V, which keeps the names) against the C++ mirrors
// (src/gpu/device_layout.hpp, math::PrimitiveParams, PrunedCell); and each kernel's workgroup
// size against the one the host plans its dispatches with. Needs no Vulkan device.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <map>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "src/gpu/device_layout.hpp"
#ifdef SDFPRUNE_REFLECT_SPV
#include "src/gpu/vk_context.hpp"  // kWorkgroupSize
#endif

namespace sdfprune::test {
namespace {

// ---- a minimal SPIR-V reader: names, layout decorations and the types they apply to ----------

enum Op : uint32_t {
    kOpName = 5,
    kOpExecutionMode = 16,
    kOpMemberName = 6,
    kOpTypeInt = 21,
    kOpTypeFloat = 22,
    kOpTypeVector = 23,
    kOpTypeArray = 28,
    kOpTypeRuntimeArray = 29,
    kOpTypeStruct = 30,
    kOpConstant = 43,
    kOpDecorate = 71,
    kOpMemberDecorate = 72,
};
constexpr uint32_t kDecorationBlock = 2, kDecorationBufferBlock = 3, kDecorationArrayStride = 6,
                   kDecorationOffset = 35;
constexpr uint32_t kExecutionModeLocalSize = 17;

struct SpirvType {
    uint32_t op = 0;
    std::vector<uint32_t> operands;  // the instruction's words after the result id
};

struct SpirvModule {
    std::string error;  // empty if the file was read
    std::map<uint32_t, std::string> names;
    std::map<std::pair<uint32_t, uint32_t>, std::string> member_names;
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> offsets;  // (struct, member) → Offset
    std::map<uint32_t, uint32_t> strides;                       // array → ArrayStride
    std::set<uint32_t> blocks;                                  // Block or BufferBlock
    std::map<uint32_t, SpirvType> types;
    std::map<uint32_t, uint32_t> constants;  // first word of each OpConstant
    uint32_t local_size[3] = {0, 0, 0};      // the entry point's LocalSize execution mode

    std::string name(uint32_t id) const {
        auto it = names.find(id);
        return it != names.end() ? it->second : "<unnamed %" + std::to_string(id) + ">";
    }
    bool has_offsets(uint32_t id) const {
        auto it = offsets.lower_bound({id, 0});
        return it != offsets.end() && it->first.first == id;
    }
};

// A literal string: UTF-8, nul-terminated, packed 4 bytes a word (little-endian words).
std::string read_string(const uint32_t* words, size_t count) {
    std::string s;
    for (size_t i = 0; i < count; ++i)
        for (int b = 0; b < 4; ++b) {
            char c = char((words[i] >> (8 * b)) & 0xffu);
            if (c == '\0') return s;
            s += c;
        }
    return s;
}

SpirvModule read_spirv(std::span<const uint32_t> words, const std::string& path) {
    SpirvModule m;
    if (words.size() < 5) {
        m.error = path + ": not a SPIR-V module (" + std::to_string(words.size()) + " words)";
        return m;
    }
    if (words[0] != 0x07230203u) {
        m.error = path + ": bad SPIR-V magic number";
        return m;
    }
    for (size_t at = 5; at < words.size();) {
        const uint32_t count = words[at] >> 16, op = words[at] & 0xffffu;
        if (count == 0 || at + count > words.size()) {
            m.error = path + ": truncated instruction at word " + std::to_string(at);
            return m;
        }
        const uint32_t* w = &words[at + 1];  // the operands
        const size_t n = count - 1;
        switch (op) {
            case kOpName:
                if (n >= 2) m.names[w[0]] = read_string(w + 1, n - 1);
                break;
            case kOpMemberName:
                if (n >= 3) m.member_names[{w[0], w[1]}] = read_string(w + 2, n - 2);
                break;
            case kOpDecorate:
                if (n >= 3 && w[1] == kDecorationArrayStride) m.strides[w[0]] = w[2];
                if (n >= 2 && (w[1] == kDecorationBlock || w[1] == kDecorationBufferBlock))
                    m.blocks.insert(w[0]);
                break;
            case kOpMemberDecorate:
                if (n >= 4 && w[2] == kDecorationOffset) m.offsets[{w[0], w[1]}] = w[3];
                break;
            case kOpTypeInt:
            case kOpTypeFloat:
            case kOpTypeVector:
            case kOpTypeArray:
            case kOpTypeRuntimeArray:
            case kOpTypeStruct:
                if (n >= 1) m.types[w[0]] = SpirvType{op, std::vector<uint32_t>(w + 1, w + n)};
                break;
            case kOpConstant:
                if (n >= 3) m.constants[w[1]] = w[2];
                break;
            case kOpExecutionMode:
                if (n >= 5 && w[1] == kExecutionModeLocalSize)
                    std::copy(w + 2, w + 5, m.local_size);
                break;
        }
        at += count;
    }
    return m;
}

// Size and alignment of a type in std430 (the layout of every buffer and push-constant block
// here); a struct's size is rounded up to its alignment, as in an array of it. Unknown types
// (bool, matrices, pointers: none in a shared block) come back as size 0 with `why` set.
struct Extent {
    uint32_t size = 0, align = 1;
};
Extent extent(const SpirvModule& m, uint32_t type, std::string& why) {
    auto it = m.types.find(type);
    if (it == m.types.end()) {
        why = "type %" + std::to_string(type) + " is not one the reader knows";
        return {};
    }
    const SpirvType& t = it->second;
    switch (t.op) {
        case kOpTypeInt:
        case kOpTypeFloat:
            return {t.operands.at(0) / 8, t.operands.at(0) / 8};
        case kOpTypeVector: {
            const Extent c = extent(m, t.operands.at(0), why);
            const uint32_t n = t.operands.at(1);
            return {c.size * n, c.size * (n == 3 ? 4 : n)};
        }
        case kOpTypeArray:
        case kOpTypeRuntimeArray: {
            const Extent e = extent(m, t.operands.at(0), why);
            auto stride = m.strides.find(type);
            if (stride == m.strides.end()) {
                why = "array %" + std::to_string(type) + " has no ArrayStride";
                return {};
            }
            if (t.op == kOpTypeRuntimeArray) return {0, e.align};
            auto length = m.constants.find(t.operands.at(1));
            if (length == m.constants.end()) {
                why = "array %" + std::to_string(type) + " has no constant length";
                return {};
            }
            return {length->second * stride->second, e.align};
        }
        case kOpTypeStruct: {
            Extent s{0, 4};
            for (uint32_t i = 0; i < t.operands.size(); ++i) {
                const Extent e = extent(m, t.operands[i], why);
                auto offset = m.offsets.find({type, i});
                if (offset != m.offsets.end()) s.size = std::max(s.size, offset->second + e.size);
                s.align = std::max(s.align, e.align);
            }
            s.size = (s.size + s.align - 1) / s.align * s.align;
            return s;
        }
    }
    why = "type %" + std::to_string(type) + " has an unexpected opcode";
    return {};
}

// ---- the C++ mirrors ---------------------------------------------------------------------------

struct Member {
    std::string name;
    size_t offset, size;
};
// Where a mirror applies: kShared, in whichever kernel declares a struct of that name;
// kPush, a kernel's push-constant block, of which the C++ struct holds exactly the bytes.
enum class Scope { kShared, kPush };
struct Mirror {
    std::string name;                  // the GLSL struct or block name
    size_t size;                       // sizeof the C++ mirror
    std::vector<std::string> kernels;  // the kernels known to use it
    std::vector<Member> members;
    Scope scope = Scope::kShared;
};
template <class T>
Mirror mirror(std::string name, std::vector<std::string> kernels, std::vector<Member> members,
              Scope scope = Scope::kShared) {
    return {std::move(name), sizeof(T), std::move(kernels), std::move(members), scope};
}
// The GLSL members carry the C++ members' names.
#define SDFPRUNE_MEMBER(T, m) (Member{#m, offsetof(T, m), sizeof(T::m)})

const std::vector<Mirror>& mirrors() {
    using namespace gpu;
    using math::PrimitiveParams;
    const std::vector<std::string> all = {"prune",
                                          "prune_bytes",
                                          "prune_refine_lanes",
                                          "prune_refine_lanes_long",
                                          "prune_refine",
                                          "prune_wide",
                                          "prune_wide_subgroups",
                                          "prune_wide_runs",
                                          "expand",
                                          "cell_info",
                                          "trace",
                                          "discretize"};
    const std::vector<std::string> scene = {
        "prune",        "prune_bytes", "prune_refine_lanes",   "prune_refine_lanes_long",
        "prune_refine", "prune_wide",  "prune_wide_subgroups", "prune_wide_runs",
        "trace",        "discretize"};
    const std::vector<std::string> grid = {"trace", "discretize"};
    static const std::vector<Mirror> table = {
        mirror<GpuNode>("Node", scene,
                        {SDFPRUNE_MEMBER(GpuNode, kind), SDFPRUNE_MEMBER(GpuNode, primitive),
                         SDFPRUNE_MEMBER(GpuNode, blend), SDFPRUNE_MEMBER(GpuNode, lipschitz)}),
        mirror<PrimitiveParams>(
            "PrimitiveParams", scene,
            {SDFPRUNE_MEMBER(PrimitiveParams, row0), SDFPRUNE_MEMBER(PrimitiveParams, row1),
             SDFPRUNE_MEMBER(PrimitiveParams, row2), SDFPRUNE_MEMBER(PrimitiveParams, a),
             SDFPRUNE_MEMBER(PrimitiveParams, b), SDFPRUNE_MEMBER(PrimitiveParams, c)}),
        mirror<GpuPrimitiveExtra>(
            "PrimitiveExtra", scene,
            {SDFPRUNE_MEMBER(GpuPrimitiveExtra, bound0), SDFPRUNE_MEMBER(GpuPrimitiveExtra, bound1),
             SDFPRUNE_MEMBER(GpuPrimitiveExtra, color)}),
        mirror<PrunedCell>(
            "Cell", all,
            {SDFPRUNE_MEMBER(PrunedCell, tape), SDFPRUNE_MEMBER(PrunedCell, children),
             SDFPRUNE_MEMBER(PrunedCell, value), SDFPRUNE_MEMBER(PrunedCell, bound)}),
        mirror<GpuBlock>(
            "Block",
            {"prune", "prune_bytes", "prune_refine_lanes", "prune_refine_lanes_long",
             "prune_refine", "prune_wide", "prune_wide_subgroups", "prune_wide_runs", "expand"},
            {SDFPRUNE_MEMBER(GpuBlock, x), SDFPRUNE_MEMBER(GpuBlock, y),
             SDFPRUNE_MEMBER(GpuBlock, z), SDFPRUNE_MEMBER(GpuBlock, tape)}),
        mirror<GpuLevel>("Level", grid,
                         {SDFPRUNE_MEMBER(GpuLevel, res), SDFPRUNE_MEMBER(GpuLevel, factor),
                          SDFPRUNE_MEMBER(GpuLevel, offset), SDFPRUNE_MEMBER(GpuLevel, pad)}),
        mirror<GpuGridParams>(
            "GridParams", grid,
            {SDFPRUNE_MEMBER(GpuGridParams, aabb_min), SDFPRUNE_MEMBER(GpuGridParams, aabb_max),
             SDFPRUNE_MEMBER(GpuGridParams, cell_size), SDFPRUNE_MEMBER(GpuGridParams, inv_cell)}),
        mirror<GpuCounters>(
            "Counters",
            {"prune", "prune_bytes", "prune_refine_lanes", "prune_refine_lanes_long",
             "prune_refine", "prune_wide", "prune_wide_subgroups", "prune_wide_runs", "expand"},
            {SDFPRUNE_MEMBER(GpuCounters, pool_used),
             SDFPRUNE_MEMBER(GpuCounters, pool_capacity),
             SDFPRUNE_MEMBER(GpuCounters, overflow),
             SDFPRUNE_MEMBER(GpuCounters, max_len),
             SDFPRUNE_MEMBER(GpuCounters, near_jobs),
             SDFPRUNE_MEMBER(GpuCounters, next_blocks),
             SDFPRUNE_MEMBER(GpuCounters, max_depth),
             SDFPRUNE_MEMBER(GpuCounters, octant_used),
             SDFPRUNE_MEMBER(GpuCounters, octant_capacity),
             SDFPRUNE_MEMBER(GpuCounters, near_words),
             SDFPRUNE_MEMBER(GpuCounters, refine_cells),
             SDFPRUNE_MEMBER(GpuCounters, near_lo),
             SDFPRUNE_MEMBER(GpuCounters, near_hi),
             SDFPRUNE_MEMBER(GpuCounters, long_jobs),
             SDFPRUNE_MEMBER(GpuCounters, more_jobs),
             SDFPRUNE_MEMBER(GpuCounters, copy_cells),
             SDFPRUNE_MEMBER(GpuCounters, walk_cells),
             SDFPRUNE_MEMBER(GpuCounters, walk_placed),
             SDFPRUNE_MEMBER(GpuCounters, scratch_claimed),
             SDFPRUNE_MEMBER(GpuCounters, order_count),
             SDFPRUNE_MEMBER(GpuCounters, order_placed),
             SDFPRUNE_MEMBER(GpuCounters, jobs_taken),
             SDFPRUNE_MEMBER(GpuCounters, walk_words),
             SDFPRUNE_MEMBER(GpuCounters, walk_sum),
             SDFPRUNE_MEMBER(GpuCounters, more_class)}),
        mirror<TraceParams>(
            "TraceParams", {"trace"},
            {SDFPRUNE_MEMBER(TraceParams, grid), SDFPRUNE_MEMBER(TraceParams, march_min),
             SDFPRUNE_MEMBER(TraceParams, march_max), SDFPRUNE_MEMBER(TraceParams, eye),
             SDFPRUNE_MEMBER(TraceParams, forward), SDFPRUNE_MEMBER(TraceParams, right),
             SDFPRUNE_MEMBER(TraceParams, up), SDFPRUNE_MEMBER(TraceParams, light),
             SDFPRUNE_MEMBER(TraceParams, width), SDFPRUNE_MEMBER(TraceParams, height),
             SDFPRUNE_MEMBER(TraceParams, shading), SDFPRUNE_MEMBER(TraceParams, shadows)}),
        mirror<GpuPixel>("Pixel", {"trace"},
                         {SDFPRUNE_MEMBER(GpuPixel, color), SDFPRUNE_MEMBER(GpuPixel, evals),
                          SDFPRUNE_MEMBER(GpuPixel, steps), SDFPRUNE_MEMBER(GpuPixel, pad0),
                          SDFPRUNE_MEMBER(GpuPixel, pad1)}),
        mirror<DiscretizeParams>(
            "DiscretizeParams", {"discretize"},
            {SDFPRUNE_MEMBER(DiscretizeParams, grid),
             SDFPRUNE_MEMBER(DiscretizeParams, sample_size), SDFPRUNE_MEMBER(DiscretizeParams, n),
             SDFPRUNE_MEMBER(DiscretizeParams, pad0), SDFPRUNE_MEMBER(DiscretizeParams, pad1),
             SDFPRUNE_MEMBER(DiscretizeParams, pad2)}),
        mirror<PrunePush>(
            "Push",
            {"prune", "prune_bytes", "prune_refine_lanes", "prune_refine_lanes_long",
             "prune_refine", "prune_wide", "prune_wide_subgroups", "prune_wide_runs"},
            {SDFPRUNE_MEMBER(PrunePush, origin),       SDFPRUNE_MEMBER(PrunePush, csize),
             SDFPRUNE_MEMBER(PrunePush, mode),         SDFPRUNE_MEMBER(PrunePush, factor),
             SDFPRUNE_MEMBER(PrunePush, jobs),         SDFPRUNE_MEMBER(PrunePush, threads),
             SDFPRUNE_MEMBER(PrunePush, max_len),      SDFPRUNE_MEMBER(PrunePush, max_stack),
             SDFPRUNE_MEMBER(PrunePush, flags),        SDFPRUNE_MEMBER(PrunePush, pool_start),
             SDFPRUNE_MEMBER(PrunePush, first_job),    SDFPRUNE_MEMBER(PrunePush, round),
             SDFPRUNE_MEMBER(PrunePush, budget),       SDFPRUNE_MEMBER(PrunePush, refine),
             SDFPRUNE_MEMBER(PrunePush, octant_start), SDFPRUNE_MEMBER(PrunePush, list_start),
             SDFPRUNE_MEMBER(PrunePush, lane_tape),    SDFPRUNE_MEMBER(PrunePush, wide_split),
             SDFPRUNE_MEMBER(PrunePush, more_start),   SDFPRUNE_MEMBER(PrunePush, group_base),
             SDFPRUNE_MEMBER(PrunePush, order_start),  SDFPRUNE_MEMBER(PrunePush, order_first),
             SDFPRUNE_MEMBER(PrunePush, claim_words),  SDFPRUNE_MEMBER(PrunePush, walk_slot)},
            Scope::kPush),
        mirror<ExpandPush>(
            "Push", {"expand"},
            {SDFPRUNE_MEMBER(ExpandPush, factor), SDFPRUNE_MEMBER(ExpandPush, cells_count),
             SDFPRUNE_MEMBER(ExpandPush, next_factor), SDFPRUNE_MEMBER(ExpandPush, bound_only)},
            Scope::kPush),
        mirror<CellInfoPush>("Push", {"cell_info"}, {SDFPRUNE_MEMBER(CellInfoPush, cells_count)},
                             Scope::kPush),
        mirror<SlicePush>(
            "Push", {"trace", "discretize"},
            {SDFPRUNE_MEMBER(SlicePush, first), SDFPRUNE_MEMBER(SlicePush, count),
             SDFPRUNE_MEMBER(SlicePush, stack_threads), SDFPRUNE_MEMBER(SlicePush, base),
             SDFPRUNE_MEMBER(SlicePush, full_tree_pass), SDFPRUNE_MEMBER(SlicePush, full_tree_fits),
             SDFPRUNE_MEMBER(SlicePush, deferred_capacity), SDFPRUNE_MEMBER(SlicePush, loop_probe)},
            Scope::kPush),
    };
    return table;
}
#undef SDFPRUNE_MEMBER

bool uses(const Mirror& mirror, const std::string& kernel) {
    return std::find(mirror.kernels.begin(), mirror.kernels.end(), kernel) != mirror.kernels.end();
}

// ---- the checks ----------------------------------------------------------------------------

// One decorated struct against its mirror: the same members in the same order at the same
// offsets and of the same sizes; its bytes fit the C++ struct (a push-constant block: the C++
// struct is exactly its bytes, up to the alignment both sides round to).
void check_struct(const SpirvModule& m, const std::string& kernel, uint32_t id,
                  const Mirror& mirror) {
    const std::vector<uint32_t>& members = m.types.at(id).operands;
    const std::string where = kernel + ".comp: " + mirror.name;
    EXPECT_EQ(members.size(), mirror.members.size())
        << where << " has " << members.size() << " members in GLSL, " << mirror.members.size()
        << " in the C++ mirror";
    for (uint32_t i = 0; i < std::min<size_t>(members.size(), mirror.members.size()); ++i) {
        const Member& want = mirror.members[i];
        auto name = m.member_names.find({id, i});
        const std::string glsl_name = name != m.member_names.end() ? name->second : "?";
        EXPECT_EQ(glsl_name, want.name) << where << ": member " << i << " is `" << glsl_name
                                        << "` in GLSL, `" << want.name << "` in the C++ mirror";
        auto offset = m.offsets.find({id, i});
        if (offset == m.offsets.end()) {
            ADD_FAILURE() << where << "." << glsl_name << " has no Offset";
            continue;
        }
        EXPECT_EQ(offset->second, want.offset)
            << where << "." << glsl_name << ": offset " << offset->second
            << " in GLSL, offsetof = " << want.offset << " in C++";
        std::string why;
        const Extent e = extent(m, members[i], why);
        EXPECT_EQ(why, "") << where << "." << glsl_name;
        EXPECT_EQ(e.size, want.size) << where << "." << glsl_name << ": " << e.size
                                     << " bytes in GLSL, " << want.size << " in C++";
    }
    std::string why;
    const Extent e = extent(m, id, why);
    EXPECT_EQ(why, "") << where;
    if (mirror.scope == Scope::kPush) {
        EXPECT_EQ(e.size, mirror.size)
            << where << ": the push-constant block is " << e.size
            << " bytes (std430, rounded to its alignment), sizeof in C++ is " << mirror.size;
    } else {
        // e.size is rounded up to the GLSL alignment; the C++ struct may add members after
        // (GpuCounters' pad) but must hold every GLSL byte.
        EXPECT_LE(e.size, mirror.size) << where << ": " << e.size << " bytes in GLSL, sizeof in "
                                       << "C++ is " << mirror.size;
    }
}

// A decorated struct without a mirror must only wrap one: a buffer block whose one member, at
// offset 0, is a runtime array or a struct (Nodes { Node nodes[]; }, TraceParamBlock
// { TraceParams prm; }). Anything else is a shared layout the host has no mirror of.
void check_wrapper(const SpirvModule& m, const std::string& kernel, uint32_t id) {
    const std::string where = kernel + ".comp: " + m.name(id);
    const std::vector<uint32_t>& members = m.types.at(id).operands;
    bool ok = m.blocks.count(id) && members.size() == 1 && m.offsets.count({id, 0}) &&
              m.offsets.at({id, 0}) == 0;
    if (ok) {
        auto t = m.types.find(members[0]);
        ok = t != m.types.end() &&
             (t->second.op == kOpTypeRuntimeArray || t->second.op == kOpTypeStruct);
    }
    if (!ok)
        ADD_FAILURE() << where << " is a struct with explicit layout that has no C++ mirror in "
                      << "tests/gpu_layout_test.cpp (add one to src/gpu/device_layout.hpp and "
                      << "the table), and is not a buffer block wrapping one runtime array or "
                      << "one struct at offset 0";
}

// The kernels' unoptimized SPIR-V, embedded at build time; none without the GPU backend.
struct EmbeddedKernel {
    const char* name;
    std::span<const uint32_t> words;
};
#ifdef SDFPRUNE_REFLECT_SPV
constexpr uint32_t kPruneSpv[] = {
#include "prune.reflect.spv.inc"
};
constexpr uint32_t kPruneBytesSpv[] = {
#include "prune_bytes.reflect.spv.inc"
};
constexpr uint32_t kPruneRefineLanesSpv[] = {
#include "prune_refine_lanes.reflect.spv.inc"
};
constexpr uint32_t kPruneRefineLanesLongSpv[] = {
#include "prune_refine_lanes_long.reflect.spv.inc"
};
constexpr uint32_t kPruneRefineSpv[] = {
#include "prune_refine.reflect.spv.inc"
};
constexpr uint32_t kPruneWideSpv[] = {
#include "prune_wide.reflect.spv.inc"
};
constexpr uint32_t kPruneWideSubgroupsSpv[] = {
#include "prune_wide_subgroups.reflect.spv.inc"
};
constexpr uint32_t kPruneWideRunsSpv[] = {
#include "prune_wide_runs.reflect.spv.inc"
};
constexpr uint32_t kExpandSpv[] = {
#include "expand.reflect.spv.inc"
};
constexpr uint32_t kCellInfoSpv[] = {
#include "cell_info.reflect.spv.inc"
};
constexpr uint32_t kTraceSpv[] = {
#include "trace.reflect.spv.inc"
};
constexpr uint32_t kDiscretizeSpv[] = {
#include "discretize.reflect.spv.inc"
};
const EmbeddedKernel kKernels[] = {{"prune", kPruneSpv},
                                   {"prune_bytes", kPruneBytesSpv},
                                   {"prune_refine_lanes", kPruneRefineLanesSpv},
                                   {"prune_refine_lanes_long", kPruneRefineLanesLongSpv},
                                   {"prune_refine", kPruneRefineSpv},
                                   {"prune_wide", kPruneWideSpv},
                                   {"prune_wide_subgroups", kPruneWideSubgroupsSpv},
                                   {"prune_wide_runs", kPruneWideRunsSpv},
                                   {"expand", kExpandSpv},
                                   {"cell_info", kCellInfoSpv},
                                   {"trace", kTraceSpv},
                                   {"discretize", kDiscretizeSpv}};
#else
const std::vector<EmbeddedKernel> kKernels;
#endif

void check_kernel(const std::string& kernel) {
    const EmbeddedKernel* found_kernel = nullptr;
    for (const EmbeddedKernel& k : kKernels)
        if (kernel == k.name) found_kernel = &k;
#ifndef SDFPRUNE_REFLECT_SPV
    GTEST_SKIP() << "built without the Vulkan backend";
#endif
    ASSERT_NE(found_kernel, nullptr) << "no embedded SPIR-V for kernel " << kernel;
    const SpirvModule m = read_spirv(found_kernel->words, kernel + ".reflect.spv");
    ASSERT_EQ(m.error, "");
    ASSERT_FALSE(m.names.empty()) << kernel << ".reflect.spv has no OpName: compiled with -O?";
#ifdef SDFPRUNE_REFLECT_SPV
    // The workgroup size the host counts lanes and workgroups with (gpu_prune_plan.cpp,
    // gpu_render.cpp): the wide kernels' kPruneWide lanes, every other kernel's kWorkgroupSize.
    const uint32_t lanes =
        kernel.starts_with("prune_wide") ? uint32_t(gpu::kPruneWide) : gpu::kWorkgroupSize;
    EXPECT_EQ(m.local_size[0], lanes) << kernel << ".comp: local_size_x " << m.local_size[0]
                                      << ", the host plans " << lanes << " lanes a workgroup";
    EXPECT_EQ(m.local_size[1], 1u) << kernel << ".comp: local_size_y";
    EXPECT_EQ(m.local_size[2], 1u) << kernel << ".comp: local_size_z";
#endif

    std::map<std::string, const Mirror*> table;
    for (const Mirror& mirror : mirrors()) {
        if (mirror.scope != Scope::kShared && !uses(mirror, kernel)) continue;
        ASSERT_TRUE(table.emplace(mirror.name, &mirror).second)
            << "two mirrors of " << mirror.name << " apply to " << kernel;
    }

    // Every struct with explicit layout (Offset decorations) is mirrored or only wraps one;
    // glslc's undecorated copies of a struct (function locals) have no host side.
    std::set<std::string> found;
    for (const auto& [id, type] : m.types) {
        if (type.op != kOpTypeStruct || !m.has_offsets(id)) continue;
        auto mirror = table.find(m.name(id));
        if (mirror == table.end()) {
            check_wrapper(m, kernel, id);
            continue;
        }
        found.insert(mirror->first);
        check_struct(m, kernel, id, *mirror->second);
    }
    // Arrays of a mirrored struct step by its sizeof.
    for (const auto& [id, type] : m.types) {
        if (type.op != kOpTypeRuntimeArray && type.op != kOpTypeArray) continue;
        const uint32_t element = type.operands.at(0);
        if (!m.has_offsets(element)) continue;
        auto mirror = table.find(m.name(element));
        if (mirror == table.end()) continue;
        auto stride = m.strides.find(id);
        if (stride == m.strides.end()) {
            ADD_FAILURE() << kernel << ".comp: an array of " << mirror->first
                          << " has no ArrayStride";
            continue;
        }
        EXPECT_EQ(stride->second, mirror->second->size)
            << kernel << ".comp: an array of " << mirror->first << " has ArrayStride "
            << stride->second << ", sizeof in C++ is " << mirror->second->size;
    }
    // The reader found what the kernel is known to share, so the above was not vacuous.
    for (const Mirror& mirror : mirrors()) {
        if (!uses(mirror, kernel)) continue;
        EXPECT_TRUE(found.count(mirror.name))
            << kernel << ".comp: no struct " << mirror.name << " with explicit layout found";
    }
}

TEST(GpuLayout, Prune) {
    check_kernel("prune");
}
TEST(GpuLayout, PruneBytes) {
    check_kernel("prune_bytes");
}
TEST(GpuLayout, PruneRefineLanes) {
    check_kernel("prune_refine_lanes");
}
TEST(GpuLayout, PruneRefineLanesLong) {
    check_kernel("prune_refine_lanes_long");
}
TEST(GpuLayout, PruneRefine) {
    check_kernel("prune_refine");
}
TEST(GpuLayout, PruneWide) {
    check_kernel("prune_wide");
}
TEST(GpuLayout, PruneWideSubgroups) {
    check_kernel("prune_wide_subgroups");
}
TEST(GpuLayout, PruneWideRuns) {
    check_kernel("prune_wide_runs");
}
TEST(GpuLayout, Expand) {
    check_kernel("expand");
}
TEST(GpuLayout, CellInfo) {
    check_kernel("cell_info");
}
TEST(GpuLayout, Trace) {
    check_kernel("trace");
}
TEST(GpuLayout, Discretize) {
    check_kernel("discretize");
}

}  // namespace
}  // namespace sdfprune::test

// C shim over tinybvh (the `tiny_bvh.h` that tinybvh-rs 0.1.0-beta.3 bundles, v1.6.8).
//
// tinybvh-rs does not expose BuildAVX, thread control (`threadedBuild`) or the BVH2 refit on a
// build of our choice, so this file compiles the same header a second time under a renamed
// namespace (so its symbols do not collide with tinybvh-rs's copy) and exposes a handful of
// plain C functions to Rust. Everything here mirrors what tinybvh's own BVH8_CPU::Build does
// (BVH2 build -> PrepareBuild4_8 -> Compact -> MBVH<8>::ConvertFrom -> BVH8_CPU::ConvertFrom),
// split into steps so the benchmark can time them separately and read the BVH2 nodes for SAH.

#define tinybvh tinybvh_peers
#define TINYBVH_IMPLEMENTATION
#include "tiny_bvh.h"

#include <cstdint>
#include <cstring>

using namespace tinybvh_peers;

namespace {

struct Handle {
    BVH8_CPU bvh8;  // owns an MBVH<8> which owns the BVH2 we build into (bvh8.bvh8.bvh)
    bvhvec4slice verts;
};

BVH& bvh2_of(Handle* h) { return h->bvh8.bvh8.bvh; }

}  // namespace

extern "C" {

// One triangle = three consecutive 16-byte vertices (x, y, z, pad), tinybvh's preferred input.
void* tbp_new() { return new Handle(); }

void tbp_free(void* p) { delete static_cast<Handle*>(p); }

// kind: 0 = Build (reference binned SAH, 8 bins), 1 = BuildAVX, 2 = BuildHQ (SBVH).
// threaded: 0 forces tinybvh's single-threaded path, 1 lets it use its job system
// (hardware_concurrency() threads; tinybvh itself disables threading below 50k triangles).
void tbp_build_bvh2(void* p, const float* verts4, uint32_t tri_count, int kind, int threaded) {
    Handle* h = static_cast<Handle*>(p);
    h->verts = bvhvec4slice(reinterpret_cast<const bvhvec4*>(verts4), tri_count * 3, sizeof(bvhvec4));
    BVH& b = bvh2_of(h);
    b.context = h->bvh8.bvh8.context = h->bvh8.context;
    b.threadedBuild = threaded != 0;
    switch (kind) {
        case 0: b.Build(h->verts); break;
        case 1: b.BuildAVX(h->verts); break;
        default: b.BuildHQ(h->verts); break;
    }
}

// The BVH2 nodes (32-byte Wald nodes: min.xyz, leftFirst, max.xyz, triCount). Root = node 0,
// children of an interior node are leftFirst and leftFirst + 1; node 1 is unused.
const void* tbp_bvh2_nodes(void* p, uint32_t* used_nodes, uint32_t* idx_count) {
    BVH& b = bvh2_of(static_cast<Handle*>(p));
    *used_nodes = b.usedNodes;
    *idx_count = b.idxCount;
    return b.bvhNode;
}

float tbp_bvh2_sahcost(void* p) { return bvh2_of(static_cast<Handle*>(p)).SAHCost(0); }

// Widen to the BVH8_CPU layout exactly as BVH8_CPU::Build does.
void tbp_convert_bvh8(void* p) {
    Handle* h = static_cast<Handle*>(p);
    BVH& b = bvh2_of(h);
    b.PrepareBuild4_8();
    b.Compact();
    h->bvh8.bvh8.ConvertFrom(b, true);
    h->bvh8.ConvertFrom(h->bvh8.bvh8);
}

// Bytes of the BVH8_CPU structure: 64-byte blocks of interleaved 256-B nodes and 192-B
// four-triangle SoA leaves (triangle data included, self-contained).
uint64_t tbp_bvh8_bytes(void* p) {
    Handle* h = static_cast<Handle*>(p);
    return uint64_t(h->bvh8.usedBlocks) * 64;
}

// rays: n x (ox, oy, oz, dx, dy, dz); closest hit, t in [0, inf). Miss: t = +inf, prim = ~0.
void tbp_trace_bvh8(void* p, const float* rays, uint32_t n, float* t_out, uint32_t* prim_out) {
    Handle* h = static_cast<Handle*>(p);
    const BVH8_CPU& b = h->bvh8;
    for (uint32_t i = 0; i < n; i++) {
        const float* r = rays + size_t(i) * 6;
        Ray ray(bvhvec3(r[0], r[1], r[2]), bvhvec3(r[3], r[4], r[5]), BVH_FAR);
        b.Intersect(ray);
        if (ray.hit.t < BVH_FAR) {
            t_out[i] = ray.hit.t;
            prim_out[i] = ray.hit.prim;
        } else {
            t_out[i] = __builtin_inff();
            prim_out[i] = 0xffffffffu;
        }
    }
}

// ---- BVH2 refit (tinybvh's BVH::Refit: single-threaded, nodes only; the triangles stay in
// the caller's vertex buffer, which the caller rewrites before each refit).
void* tbp_refit_new(const float* verts4, uint32_t tri_count) {
    BVH* b = new BVH();
    b->threadedBuild = false;  // a hole-free node list is required by Refit
    b->Build(bvhvec4slice(reinterpret_cast<const bvhvec4*>(verts4), tri_count * 3, sizeof(bvhvec4)));
    return b;
}
void tbp_refit(void* p) { static_cast<BVH*>(p)->Refit(); }
float tbp_refit_sahcost(void* p) { return static_cast<BVH*>(p)->SAHCost(0); }
void tbp_refit_free(void* p) { delete static_cast<BVH*>(p); }

}  // extern "C"

// What a pass keeps of a pixel sample beside its radiance, each behind the
// switch of the passes that read it: footprint samples' state
// (FOOTPRINT_AA), the camera ray's first interaction and the end of its
// principal chain (ADAPTIVE_FIRST, adaptive_first.frag), the rays traced
// (the cost view, VIEW_MODE 3, and the adaptive first pass).

#ifdef FOOTPRINT_AA
// Footprint samples: in adaptive renders, and in uniform renders of more
// than one sample (viewer/gpu/renderer.py).  footprint_shares.frag: no
// tracing, each pixel's closed-form share only (AdaptiveSampler.share_pass).
#include "footprint.glsl"
#endif

// The pixel's and the sample's footprint state (lib/footprint.glsl), set
// before their rays are traced; nothing without footprint samples.
void footprintPixel(vec2 ij) {
#ifdef FOOTPRINT_AA
    setFootprintPixel(ij);
#endif
}

void footprintSample(vec2 offset) {
#ifdef FOOTPRINT_AA
    setFootprintSample(offset);
#endif
}

#ifdef ADAPTIVE_FIRST
float firstT = INF;
int firstObject = -1;
vec3 firstChecker = vec3(0.0);
// Where the camera ray's principal chain (see Branch) ends on an opaque
// surface: (x, z camera-relative, chain id, object); object -1: it leaves
// the scene (x, z 0; the id still the chain's) or is cut (max_depth,
// min_weight) first (all 0).
vec4 chainLeaf = vec4(0.0, 0.0, 0.0, -1.0);
#define RECORD_FIRST(br, it) if (br.depth == 1) { firstT = length(it.p - br.o); firstObject = it.object; }
#else
#define RECORD_FIRST(br, it)
#endif

#if (defined(VIEW_MODE) && VIEW_MODE == 3) || defined(ADAPTIVE_FIRST)
int rayCount = 0;           // the cost view: rays traced for this pixel sample
#define COUNT_RAY() (++rayCount)
#else
#define COUNT_RAY()
#endif

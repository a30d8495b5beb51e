// llvmpipe's loop limit, as the resumable passes (lib/resume.glsl) and
// CUT_CHECK renders (render.frag) see it.

uniform int loopProbe;         // 2 (a loop's trip count the compiler cannot know)

// Whether llvmpipe's loop limit has been reached in this invocation: from
// then on every loop stops after its first iteration, so a two-iteration
// loop runs once.  The limit counts iterations, not nodes (a node of many
// lights or objects takes hundreds), so a RESUME pass checks after every
// node and hands back the node that was cut, to be traced again (w = 2:
// Renderer then gives the passes fewer nodes); a CUT_CHECK render marks
// the pixel (-inf) and Renderer.render draws the image again in passes.
bool loopsCut() {
    int n = 0;
    for (int i = 0; i < loopProbe; ++i) ++n;
    return n < loopProbe;
}

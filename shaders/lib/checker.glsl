// The checker's cells, shared by shading (lib/shade.glsl) and footprint
// samples (lib/footprint.glsl).

// floor(w / size) of the checker rule, per component.  A negative w has a
// negative quotient, so a cell of -1 or less; a quotient below float32's
// smallest normal (a square 1e38 or more across, |w| ~ 1) flushes to -0 and
// its floor to 0, which put the whole of x < 0 on the wrong side.
vec2 checkerCell(vec2 w, float size) {
    vec2 c = floor(w / size);
    return vec2(w.x < 0.0 ? min(c.x, -1.0) : c.x, w.y < 0.0 ? min(c.y, -1.0) : c.y);
}

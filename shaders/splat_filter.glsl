// The pixel filter of the coverage-aware splats (quality "high"), in pixels.
// FILTER (injected from aniso3d/rendering/splat/params.py): 1 the tent of radius 1 (bilinear
// weights), 2 the quadratic B-spline of radius 1.5. Both are B-splines, so
// their copies at the pixel centres sum to exactly 1 anywhere: a box-shaped
// footprint filtered by either and sampled at the pixel centres gives back
// exactly its area, wherever it lies on the pixel grid.
#ifndef FILTER
#define FILTER 1
#endif

#if FILTER == 0
#define FILTER_RADIUS 0.5
// The box's cumulative distribution function.
float filter_cdf(float x) {
    return clamp(x + 0.5, 0.0, 1.0);
}
#elif FILTER == 1
#define FILTER_RADIUS 1.0
// The tent's cumulative distribution function.
float filter_cdf(float x) {
    float a = clamp(abs(x), 0.0, 1.0);
    float h = a - 0.5 * a * a;  // integral from 0 to a
    return 0.5 + (x < 0.0 ? -h : h);
}
#else
#define FILTER_RADIUS 1.5
// The quadratic B-spline's cumulative distribution function.
float filter_cdf(float x) {
    float a = min(abs(x), 1.5);
    float h = a <= 0.5 ? a * (0.75 - a * a / 3.0) : (1.0 / 3.0) + (1.0 - pow(1.5 - a, 3.0)) / 6.0;
    return 0.5 + (x < 0.0 ? -h : h);
}
#endif

// The interval [-b, b] filtered, at offset t (pixels); b >= 0.
float filtered_interval(float t, float b) {
    return filter_cdf(t + b) - filter_cdf(t - b);
}

// A clip plane's line in the image (a row over (1, x, y)): c (L . (1, x, y))
// is positive where the splat is kept. The area of the rectangle [lo, hi]
// on the kept side, exactly: the kept height along the axis the line is
// flatter to is a clamped linear function z of the other coordinate,
// integrated in closed form (P, the integral of clamp(z, 0, H)).
float clamp_integral(float z, float h) {
    float a = max(z, 0.0);
    float b = max(z - h, 0.0);
    return 0.5 * (a * a - b * b);
}
float rect_kept(vec2 lo, vec2 hi, vec3 l) {
    vec2 size = max(hi - lo, 0.0);
    float full = size.x * size.y;
    if (full <= 0.0) return 0.0;
    vec2 g = l.yz;
    if (abs(g.x) > abs(g.y)) {
        lo = lo.yx;
        hi = hi.yx;
        g = g.yx;
        size = size.yx;
    }
    if (g.y == 0.0) return l.x >= 0.0 ? full : 0.0;
    // The line y = c + m x; kept above it where g.y > 0, below where g.y < 0.
    float m = -g.x / g.y;
    float c = -l.x / g.y;
    float y0 = c + m * lo.x;
    float y1 = c + m * hi.x;
    float z0 = g.y > 0.0 ? hi.y - y0 : y0 - lo.y;
    float z1 = g.y > 0.0 ? hi.y - y1 : y1 - lo.y;
    float dz = z1 - z0;
    if (abs(dz) < 1e-3 * size.x) return size.x * clamp(0.5 * (z0 + z1), 0.0, size.y);
    return size.x * (clamp_integral(z1, size.y) - clamp_integral(z0, size.y)) / dz;
}

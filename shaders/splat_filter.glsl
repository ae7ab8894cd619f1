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

#version 430
// Volume renderer (b), the start pass, fragment stage: each pixel keeps (by
// MIN blending into an R32F target cleared to BIG) the nearest distance
// along u_forward beyond the ray base at which its ray enters a widened
// occupied brick box (front faces only). volume.frag (START_PASS) starts the
// ray there, and discards a pixel whose ray enters none.
in float v_s;
out float f_s;

void main() {
    f_s = v_s;
}

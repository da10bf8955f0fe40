// The viewer's overlay: one texture drawn into a rectangle of the window (the rendered
// frame, texel for pixel, and the heads-up text over it, blended by its alpha).
// Row 0 of the texture is the top row of the image, as plantgen's images are stored.

#if defined VERTEX_SHADER

uniform vec4 rect;            // x0, y0, x1, y1 in normalised device coordinates
out vec2 v_uv;

void main() {
    vec2 corner = vec2(gl_VertexID & 1, (gl_VertexID >> 1) & 1);   // a triangle strip of 4
    v_uv = vec2(corner.x, 1.0 - corner.y);
    gl_Position = vec4(mix(rect.xy, rect.zw, corner), 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D image;
in vec2 v_uv;
layout(location = 0) out vec4 out_color;

void main() {
    out_color = texture(image, v_uv);
}

#endif

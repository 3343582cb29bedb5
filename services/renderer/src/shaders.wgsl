// The scene pass: blocks, hand, floor and planar shadows, drawn once per eye into that eye's
// viewport. Colours are linear; the target is sRGB.

struct Globals {
    // Unit vector towards the (directional) light.
    light_dir: vec4<f32>,
    // x: shadow height above the floor (m), y: shadow darkness (0..1).
    params: vec4<f32>,
};

struct EyeUniform {
    view_proj: mat4x4<f32>,
    eye_pos: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var<uniform> eye: EyeUniform;

struct VIn {
    @location(0) position: vec3<f32>,
    // Edge weights: the smallest is 0 on a face's outline (mesh.rs).
    @location(1) edge: vec4<f32>,
    @location(2) m0: vec4<f32>,
    @location(3) m1: vec4<f32>,
    @location(4) m2: vec4<f32>,
    @location(5) m3: vec4<f32>,
    // rgb: linear colour; a: 1 to draw the mesh's polygon edges.
    @location(6) color: vec4<f32>,
};

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) edge: vec4<f32>,
    @location(2) color: vec4<f32>,
};

fn world_of(v: VIn) -> vec3<f32> {
    let m = mat4x4<f32>(v.m0, v.m1, v.m2, v.m3);
    return (m * vec4<f32>(v.position, 1.0)).xyz;
}

@vertex
fn vs_main(v: VIn) -> VOut {
    let w = world_of(v);
    var o: VOut;
    o.clip = eye.view_proj * vec4<f32>(w, 1.0);
    o.world = w;
    o.edge = v.edge;
    o.color = v.color;
    return o;
}

// Planar shadow: the vertex slides along the light direction onto the floor (y = 0), drawn
// just above it.
@vertex
fn vs_shadow(v: VIn) -> VOut {
    let w = world_of(v);
    let l = globals.light_dir.xyz;
    var p = w - l * (max(w.y, 0.0) / l.y);
    p.y = globals.params.x;
    var o: VOut;
    o.clip = eye.view_proj * vec4<f32>(p, 1.0);
    o.world = p;
    o.edge = vec4<f32>(1.0);
    o.color = v.color;
    return o;
}

const FLOOR: vec3<f32> = vec3<f32>(0.42, 0.42, 0.40);

fn floor_light() -> f32 {
    return 0.45 + 0.55 * max(globals.light_dir.y, 0.0);
}

@fragment
fn fs_floor(i: VOut) -> @location(0) vec4<f32> {
    return vec4<f32>(FLOOR * floor_light(), 1.0);
}

@fragment
fn fs_shadow(i: VOut) -> @location(0) vec4<f32> {
    return vec4<f32>(FLOOR * floor_light() * (1.0 - globals.params.y), 1.0);
}

// Grid lines (line geometry; the edge weight is the line's strength), faded out with distance
// where they crowd into moire patterns.
@fragment
fn fs_grid(i: VOut) -> @location(0) vec4<f32> {
    let dist = length(eye.eye_pos.xyz - i.world);
    let k = i.edge.x * clamp(2.0 - dist / 2.0, 0.0, 1.0);
    return vec4<f32>(mix(FLOOR * floor_light(), vec3<f32>(0.10, 0.10, 0.11), k), 1.0);
}

// The outline colour of each block mode, linear: draw_list.rs's mode_color, in BlockMode's
// order (free, resting, tipping, pushed, grasped, carried, supported); a test compares them.
const MODE_RGB = array<vec3<f32>, 7>(
    vec3<f32>(0.20, 0.40, 0.95),
    vec3<f32>(0.80, 0.12, 0.08),
    vec3<f32>(0.95, 0.45, 0.02),
    vec3<f32>(0.90, 0.80, 0.05),
    vec3<f32>(0.08, 0.75, 0.12),
    vec3<f32>(0.55, 0.15, 0.85),
    vec3<f32>(0.05, 0.65, 0.70),
);

@fragment
fn fs_solid(i: VOut) -> @location(0) vec4<f32> {
    // Flat shading: the face normal from screen derivatives, turned towards the viewer.
    let n0 = normalize(cross(dpdx(i.world), dpdy(i.world)));
    let fw = fwidth(i.edge);
    let to_eye = eye.eye_pos.xyz - i.world;
    let n = select(n0, -n0, dot(n0, to_eye) < 0.0);
    let l = globals.light_dir.xyz;
    let diffuse = max(dot(n, l), 0.0);
    // Contact shading: darker within 3 cm of the floor, so resting and hovering differ.
    let contact = mix(0.6, 1.0, smoothstep(0.0, 0.03, i.world.y));
    var c = i.color.rgb * (0.3 + 0.7 * diffuse) * contact;
    // Polygon edges. alpha 0: none (floor, hand); else 1 + the block's mode (BlockMode's
    // index), which its outline shows (draw_list.rs, mode_color): resting (2) keeps a thin
    // dark outline in its own colour, every other mode a wider one in the mode's colour, so a
    // block keeps its own colour on its faces whatever it does.
    let d = i.edge / max(fw, vec4<f32>(1e-6));
    let e = min(min(d.x, d.y), min(d.z, d.w));
    let mode = u32(i.color.a + 0.5);
    if (mode >= 1u) {
        var edge_rgb = i.color.rgb * 0.1;
        var width = 1.0;
        if (mode != 2u) {
            var modes = MODE_RGB; // a variable: indexed at run time
            edge_rgb = modes[min(mode - 1u, 6u)];
            width = 2.5;
        }
        let k = 1.0 - smoothstep(width - 0.5, width + 0.5, e);
        c = mix(c, edge_rgb, k);
    }
    return vec4<f32>(c, 1.0);
}

// The output pass: the side-by-side eye texture to the final image (a window's surface, or
// the anaglyph). textureLoad of the sRGB texture gives linear values.

struct Composite {
    // x: 0 = copy both eyes side by side, 1 = red-cyan anaglyph; y, z: one eye's size.
    mode: vec4<u32>,
    // xy: the destination's size in pixels.
    dst: vec4<f32>,
};

@group(0) @binding(0) var eyes: texture_2d<f32>;
@group(0) @binding(1) var<uniform> comp: Composite;

@vertex
fn vs_full(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32((i << 1u) & 2u);
    let y = f32(i & 2u);
    return vec4<f32>(x * 2.0 - 1.0, 1.0 - y * 2.0, 0.0, 1.0);
}

@fragment
fn fs_composite(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let w = f32(comp.mode.y);
    let h = f32(comp.mode.z);
    let dst = comp.dst.xy;
    if (comp.mode.x == 1u) {
        let u = min(u32(pos.x * w / dst.x), comp.mode.y - 1u);
        let v = min(u32(pos.y * h / dst.y), comp.mode.z - 1u);
        let left = textureLoad(eyes, vec2<u32>(u, v), 0).rgb;
        let right = textureLoad(eyes, vec2<u32>(u + comp.mode.y, v), 0).rgb;
        // Half-colour anaglyph: red carries the left eye's luminance (a red filter passes a
        // red object and a grey one alike), green and blue carry the right eye's colour.
        let lum = dot(left, vec3<f32>(0.299, 0.587, 0.114));
        return vec4<f32>(lum, right.g, right.b, 1.0);
    }
    let u = min(u32(pos.x * 2.0 * w / dst.x), 2u * comp.mode.y - 1u);
    let v = min(u32(pos.y * h / dst.y), comp.mode.z - 1u);
    return vec4<f32>(textureLoad(eyes, vec2<u32>(u, v), 0).rgb, 1.0);
}

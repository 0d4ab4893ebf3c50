// Counts the frame's reads of the tile atlas that would find something other than what the
// frame expects: every terrain draw and grass job names the slot it reads and the identity
// ([level, x, y, generation]) that slot must hold; the atlas's identity buffer says what the
// GPU's uploads and derivations actually left there. No CPU mirror: the CPU's side of the
// comparison is the claim itself (`TileAtlas::claimed`).

struct Check {
    expected: vec4<u32>,
    // x: the atlas slot read.
    slot: vec4<u32>,
}

struct Checks {
    // x: number of checks.
    count: vec4<u32>,
    items: array<Check>,
}

@group(0) @binding(0) var<storage, read> checks: Checks;
@group(0) @binding(1) var<storage, read> identity: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> holes: array<atomic<u32>, 4>;

@compute @workgroup_size(64, 1, 1)
fn hole_check(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= checks.count.x {
        return;
    }
    let c = checks.items[gid.x];
    if c.slot.x >= arrayLength(&identity) || any(identity[c.slot.x] != c.expected) {
        atomicAdd(&holes[0], 1u);
    }
}

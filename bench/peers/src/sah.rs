//! One SAH evaluator for every library's binary tree.
//!
//! SAH = (C_trav * sum over interior nodes of A(n) + C_isect * sum over leaves of A(l) * N(l))
//!       / A(root), with C_trav = 1, C_isect = 1, A = surface area, N = primitive references in
//! the leaf (split references count once per leaf they appear in). The root counts as an
//! interior node (tinybvh's `BVH::SAHCost` convention; this reproduces it).

pub const C_TRAV: f64 = 1.0;
pub const C_ISECT: f64 = 1.0;

pub fn area(bmin: [f32; 3], bmax: [f32; 3]) -> f64 {
    let d = [0, 1, 2].map(|k| (bmax[k] as f64 - bmin[k] as f64).max(0.0));
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

pub enum Node {
    Inner { area: f64, children: [usize; 2] },
    Leaf { area: f64, count: u32 },
}

/// Walks the tree from `root` through `node(i)`.
pub fn sah(root: usize, node: impl Fn(usize) -> Node) -> f64 {
    let root_area = match node(root) {
        Node::Inner { area, .. } | Node::Leaf { area, .. } => area,
    };
    if root_area <= 0.0 {
        return f64::NAN;
    }
    let mut sum = 0.0;
    let mut stack = vec![root];
    while let Some(i) = stack.pop() {
        match node(i) {
            Node::Inner { area, children } => {
                sum += C_TRAV * area;
                stack.extend_from_slice(&children);
            }
            Node::Leaf { area, count } => sum += C_ISECT * area * count as f64,
        }
    }
    sum / root_area
}

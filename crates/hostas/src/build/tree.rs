//! The builders' output: an 8-wide tree over positions in the final primitive order. Builders
//! know geometry, not bytes; `layout::encode` turns this into bytes.

use crate::layout::WIDTH;
use crate::math::Aabb;

#[derive(Debug)]
pub enum Child {
    /// Primitives `first..first + count` of the final order.
    Leaf {
        first: u32,
        count: u32,
    },
    Inner(Box<InnerNode>),
}

/// An inner node with up to `WIDTH` children (always all of them, see the size plan), each
/// with its exact bounds.
#[derive(Debug)]
pub struct InnerNode {
    slots: [(Aabb, Child); WIDTH],
    len: u8,
    /// Inner nodes in this subtree, this one included (the encoder lays subtrees out
    /// side by side from it).
    pub nodes: u32,
}

impl InnerNode {
    pub fn new(children: impl IntoIterator<Item = (Aabb, Child)>) -> InnerNode {
        let mut node = InnerNode {
            slots: std::array::from_fn(|_| (Aabb::EMPTY, Child::Leaf { first: 0, count: 0 })),
            len: 0,
            nodes: 1,
        };
        for c in children.into_iter().take(WIDTH) {
            if let Child::Inner(n) = &c.1 {
                node.nodes += n.nodes;
            }
            node.slots[node.len as usize] = c;
            node.len += 1;
        }
        node
    }
    pub fn children(&self) -> &[(Aabb, Child)] {
        &self.slots[..self.len as usize]
    }
}

/// A built tree: `root` covers every stored primitive; `None` when there are none.
#[derive(Debug)]
pub struct Tree {
    pub root: Option<(Aabb, Child)>,
}

//! The builders' output: an 8-wide tree over positions in the final primitive order. Builders
//! know geometry, not bytes; `layout::encode` turns this into bytes.
//!
//! The inner nodes sit in one array in depth-first order (a node, then its children's subtrees
//! in slot order), the order the encoder writes them in, so encoding is a plain map over the
//! array. Builders append a node before its children (see [`NodeList`]); subtrees built on
//! other threads are appended whole, their indices shifted.

use crate::layout::WIDTH;
use crate::math::Aabb;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Child {
    /// Primitives `first..first + count` of the final order.
    Leaf { first: u32, count: u32 },
    /// Index of an inner node in [`Tree::nodes`].
    Inner(u32),
}

/// An inner node with up to `WIDTH` children (always all of them, see the size plan), each
/// with its exact bounds.
#[derive(Clone, Copy, Debug)]
pub struct InnerNode {
    slots: [(Aabb, Child); WIDTH],
    len: u8,
}

impl InnerNode {
    const PLACEHOLDER: InnerNode = InnerNode {
        slots: [(Aabb::EMPTY, Child::Leaf { first: 0, count: 0 }); WIDTH],
        len: 0,
    };
    pub fn new(children: impl IntoIterator<Item = (Aabb, Child)>) -> InnerNode {
        let mut node = InnerNode::PLACEHOLDER;
        for c in children.into_iter().take(WIDTH) {
            node.slots[node.len as usize] = c;
            node.len += 1;
        }
        node
    }
    pub fn children(&self) -> &[(Aabb, Child)] {
        &self.slots[..self.len as usize]
    }
}

/// A built tree: `root` covers every stored primitive (`None` when there are none); when it
/// is inner, it is `nodes[0]`.
#[derive(Debug)]
pub struct Tree {
    pub root: Option<(Aabb, Child)>,
    pub nodes: Vec<InnerNode>,
}

/// Inner nodes being appended in depth-first order.
#[derive(Debug, Default)]
pub struct NodeList {
    pub nodes: Vec<InnerNode>,
}

impl NodeList {
    pub fn with_capacity(n: usize) -> NodeList {
        NodeList {
            nodes: Vec::with_capacity(n),
        }
    }
    /// Appends a node to be filled in by [`NodeList::set`] once its children are built.
    #[inline]
    pub fn reserve(&mut self) -> u32 {
        self.nodes.push(InnerNode::PLACEHOLDER);
        (self.nodes.len() - 1) as u32
    }
    #[inline]
    pub fn set(&mut self, i: u32, node: InnerNode) {
        if let Some(slot) = self.nodes.get_mut(i as usize) {
            *slot = node;
        }
    }
    /// Appends a subtree built on its own (its root, if inner, at its index 0) and returns
    /// the child as it reads in this list.
    pub fn append(&mut self, child: Child, sub: NodeList) -> Child {
        let shift = self.nodes.len() as u32;
        if shift == 0 {
            self.nodes = sub.nodes;
            return child;
        }
        self.nodes.extend(sub.nodes.into_iter().map(|mut n| {
            for (_, c) in &mut n.slots[..n.len as usize] {
                if let Child::Inner(i) = c {
                    *i += shift;
                }
            }
            n
        }));
        match child {
            Child::Inner(i) => Child::Inner(i + shift),
            leaf => leaf,
        }
    }
}

/// Most inner nodes a subtree over `n` primitives needs (see `layout::plan::max_nodes`), as a
/// capacity hint.
pub fn node_hint(n: usize) -> usize {
    n.saturating_sub(1).div_ceil(WIDTH - 1) + 1
}

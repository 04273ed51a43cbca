//! A live run without sockets: the center and the nodes in one process, every datagram handed
//! straight to its receiver. What a program that embeds both sides does, and the reference the
//! tests hold the socket runs to (a node that was down for some steps is this run with its
//! datagrams of those steps lost).
use super::center::{Center, StepRecord};
use super::node::Node;
use super::wire::Datagram;

/// Runs `center` with `nodes` (node i is sensor i) to the end; `lose` says which datagrams from
/// the nodes never reach the center. Returns every fused step.
pub fn run_local(
    center: &mut Center,
    nodes: &mut [Node],
    mut lose: impl FnMut(&Datagram) -> bool,
) -> Result<Vec<StepRecord>, String> {
    let mut out = Vec::new();
    while !center.finished() {
        let announced = center.announce()?;
        for (i, node) in nodes.iter_mut().enumerate() {
            let mut to_node = vec![announced[i].clone()];
            while !to_node.is_empty() {
                let mut next = Vec::new();
                for d in &to_node {
                    for up in node.handle(d)?.datagrams {
                        let lost = Datagram::decode(&up).is_ok_and(|d| lose(&d));
                        if !lost {
                            next.extend(center.accept(&up).replies);
                        }
                    }
                }
                to_node = next;
            }
        }
        out.push(center.close()?);
    }
    Ok(out)
}

//! Two "hosts" on one machine: network namespaces joined by a veth pair, created and removed
//! by the caller (root needed). Used by `navsync-bench zenoh` and tests/tests/timing/zenoh_bridge.rs.

use std::path::Path;
use std::process::Command;

fn ip(args: &[&str]) -> Result<(), String> {
    let o = Command::new("ip").args(args).output().map_err(|e| format!("ip: {e}"))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

/// Namespaces `A` (index 0) and `B` (1), a veth pair between them with an address in each;
/// removed on drop.
pub struct NetnsPair {
    /// Namespace names.
    pub ns: [String; 2],
    /// The veth ends, one in each namespace.
    pub veth: [String; 2],
    /// IPv4 addresses of the ends (/24).
    pub addr: [String; 2],
}

impl NetnsPair {
    /// Creates them; `tag` (a few letters) keeps concurrent users apart. An error says what
    /// `ip` refused (not root, no iproute2, no namespaces).
    pub fn new(tag: &str) -> Result<Self, String> {
        let id = std::process::id() % 100_000;
        let net = (id as usize + tag.len() * 37 + tag.bytes().map(usize::from).sum::<usize>()) % 250;
        let l = NetnsPair {
            ns: [format!("{tag}A{id}"), format!("{tag}B{id}")],
            veth: [format!("{tag}a{id}"), format!("{tag}b{id}")],
            addr: [format!("10.213.{net}.1"), format!("10.213.{net}.2")],
        };
        for n in &l.ns {
            ip(&["netns", "add", n])?;
        }
        ip(&["link", "add", &l.veth[0], "type", "veth", "peer", "name", &l.veth[1]])?;
        for i in 0..2 {
            ip(&["link", "set", &l.veth[i], "netns", &l.ns[i]])?;
            l.exec(
                i,
                &["ip", "addr", "add", &format!("{}/24", l.addr[i]), "dev", &l.veth[i]],
            )?;
            l.exec(i, &["ip", "link", "set", &l.veth[i], "up"])?;
            l.exec(i, &["ip", "link", "set", "lo", "up"])?;
        }
        Ok(l)
    }

    /// Runs `args` in namespace `i` and waits for it.
    pub fn exec(&self, i: usize, args: &[&str]) -> Result<(), String> {
        let mut a = vec!["netns", "exec", &self.ns[i]];
        a.extend(args);
        ip(&a)
    }

    /// `program ARGS` to be run in namespace `i` (`ip netns exec` keeps the environment).
    pub fn command(&self, i: usize, program: &Path, args: &[&str]) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.ns[i]]).arg(program).args(args);
        c
    }

    /// Takes namespace A's end of the link down or up.
    pub fn set_link(&self, up: bool) -> Result<(), String> {
        self.exec(0, &["ip", "link", "set", &self.veth[0], if up { "up" } else { "down" }])
    }
}

impl Drop for NetnsPair {
    fn drop(&mut self) {
        for n in &self.ns {
            let _ = ip(&["netns", "del", n]);
        }
    }
}

pub use crate::util::StopOnDrop;

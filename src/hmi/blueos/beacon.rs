//! What BlueOS's beacon and helper tell Cockpit about the vehicle: its
//! addresses with the kind of link each is on (`/beacon/v1.0/services`),
//! its name (`/beacon/v1.0/vehicle_name`) and the web services it runs
//! (`/helper/v1.0/web_services`).
//!
//! Cockpit picks the video's ICE address from the first: an address on a
//! `WIRED` or `USB` link that the stream offers becomes the one it allows;
//! when the address it was given is on another kind of link it leaves the
//! choice alone; otherwise it covers the picture with "Video being routed
//! from multiple IPs". So the answer names every address of the vehicle
//! with the kind of its interface, and also the address the asker reached
//! (a loopback alias such as 127.0.0.2 is on no interface's list).
//!
//! The kind is read from sysfs ([`classify`] decides from the facts, so it
//! is tested without a machine): wireless → `WIFI`, a device on a USB bus
//! (a USB Ethernet adapter, the BeagleBone's USB gadget) → `USB`, another
//! device → `WIRED`; virtual interfaces by their name, else `UNKNOWN`
//! (loopback, bridges, tunnels). Reads only; never changes the network.

use std::net::IpAddr;
use std::path::Path;

use serde::Serialize;

/// Cockpit's names for the kinds of link (BlueOS's beacon's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum InterfaceType {
    Wired,
    Wifi,
    Usb,
    Unknown,
}

/// What sysfs and the interface's flags say about one interface.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InterfaceFacts {
    pub name: String,
    pub loopback: bool,
    /// `wireless/` or `phy80211` in its sysfs folder.
    pub wireless: bool,
    /// Where its `device` link leads (`None`: a virtual interface).
    pub device: Option<String>,
}

/// The kind of link an interface is.
pub fn classify(f: &InterfaceFacts) -> InterfaceType {
    if f.loopback {
        return InterfaceType::Unknown;
    }
    if f.wireless {
        return InterfaceType::Wifi;
    }
    match &f.device {
        Some(d) if d.contains("usb") => InterfaceType::Usb,
        Some(_) => InterfaceType::Wired,
        // Virtual: a container's veth is named like the link it stands for.
        None if f.name.starts_with("eth") || f.name.starts_with("en") => InterfaceType::Wired,
        None if f.name.starts_with("wl") => InterfaceType::Wifi,
        None if f.name.starts_with("usb") => InterfaceType::Usb,
        None => InterfaceType::Unknown,
    }
}

/// An interface's facts from `/sys/class/net/NAME`.
fn facts(name: &str, loopback: bool) -> InterfaceFacts {
    let dir = Path::new("/sys/class/net").join(name);
    InterfaceFacts {
        name: name.to_owned(),
        loopback,
        wireless: dir.join("wireless").exists() || dir.join("phy80211").exists(),
        device: std::fs::canonicalize(dir.join("device"))
            .ok()
            .map(|p| p.display().to_string()),
    }
}

/// One address as the beacon lists it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Service {
    pub service_type: &'static str,
    pub domain: String,
    pub interface: String,
    pub ip: String,
    pub interface_type: InterfaceType,
}

/// One address of an interface that is up, with its netmask.
struct Address {
    interface: String,
    ip: IpAddr,
    mask: Option<IpAddr>,
    kind: InterfaceType,
}

fn addresses() -> Vec<Address> {
    use nix::net::if_::InterfaceFlags;
    let Ok(all) = nix::ifaddrs::getifaddrs() else {
        return Vec::new();
    };
    let ip_of = |s: &nix::sys::socket::SockaddrStorage| {
        s.as_sockaddr_in()
            .map(|v4| IpAddr::V4(v4.ip()))
            .or_else(|| s.as_sockaddr_in6().map(|v6| IpAddr::V6(v6.ip())))
    };
    let mut out = Vec::new();
    for a in all {
        if !a.flags.contains(InterfaceFlags::IFF_UP) {
            continue;
        }
        let Some(ip) = a.address.as_ref().and_then(ip_of) else {
            continue;
        };
        if let IpAddr::V6(v6) = ip
            && (v6.segments()[0] & 0xffc0) == 0xfe80
        {
            continue;
        }
        let loopback = a.flags.contains(InterfaceFlags::IFF_LOOPBACK);
        out.push(Address {
            kind: classify(&facts(&a.interface_name, loopback)),
            interface: a.interface_name,
            ip,
            mask: a.netmask.as_ref().and_then(ip_of),
        });
    }
    out
}

/// Whether `ip` is in the network of `a`.
fn on_network(a: &Address, ip: IpAddr) -> bool {
    match (a.ip, a.mask, ip) {
        (IpAddr::V4(net), Some(IpAddr::V4(mask)), IpAddr::V4(ip)) => {
            u32::from(net) & u32::from(mask) == u32::from(ip) & u32::from(mask)
        }
        (IpAddr::V6(net), Some(IpAddr::V6(mask)), IpAddr::V6(ip)) => {
            u128::from(net) & u128::from(mask) == u128::from(ip) & u128::from(mask)
        }
        _ => false,
    }
}

/// The vehicle's addresses, and `reached` (the address the asker's
/// connection reached) when it is on no interface's list, with the kind of
/// the interface whose network holds it.
pub fn services(reached: Option<IpAddr>, hostname: &str) -> Vec<Service> {
    let addrs = addresses();
    let domain = format!("{hostname}.local");
    let mut out: Vec<Service> = addrs
        .iter()
        .map(|a| Service {
            service_type: "_http",
            domain: domain.clone(),
            interface: a.interface.clone(),
            ip: a.ip.to_string(),
            interface_type: a.kind,
        })
        .collect();
    if let Some(ip) = reached.map(|ip| ip.to_canonical())
        && !ip.is_unspecified()
        && !addrs.iter().any(|a| a.ip == ip)
    {
        let holder = addrs.iter().find(|a| on_network(a, ip));
        out.push(Service {
            service_type: "_http",
            domain,
            interface: holder.map_or_else(String::new, |a| a.interface.clone()),
            ip: ip.to_string(),
            interface_type: holder.map_or(InterfaceType::Unknown, |a| a.kind),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(name: &str, device: Option<&str>) -> InterfaceFacts {
        InterfaceFacts {
            name: name.into(),
            device: device.map(str::to_owned),
            ..InterfaceFacts::default()
        }
    }

    #[test]
    fn kinds_of_link() {
        // The BeagleBone's Ethernet (the OpenROV tether) and its USB gadget.
        assert_eq!(
            classify(&f(
                "eth0",
                Some("/sys/devices/platform/ocp/4a100000.ethernet")
            )),
            InterfaceType::Wired
        );
        assert_eq!(
            classify(&f(
                "usb0",
                Some(
                    "/sys/devices/platform/ocp/47400000.target-module/47401400.usb/musb-hdrc.0/gadget.0"
                )
            )),
            InterfaceType::Usb
        );
        assert_eq!(
            classify(&f(
                "enx00e04c",
                Some("/sys/devices/pci0000:00/0000:00:14.0/usb2/2-1/2-1:1.0")
            )),
            InterfaceType::Usb
        );
        let wifi = InterfaceFacts {
            wireless: true,
            ..f("wlan0", Some("/sys/devices/platform/soc/wifi"))
        };
        assert_eq!(classify(&wifi), InterfaceType::Wifi);
        let lo = InterfaceFacts {
            loopback: true,
            ..f("lo", None)
        };
        assert_eq!(classify(&lo), InterfaceType::Unknown);
        assert_eq!(classify(&f("eth0", None)), InterfaceType::Wired);
        assert_eq!(classify(&f("docker0", None)), InterfaceType::Unknown);
        assert_eq!(classify(&f("tun0", None)), InterfaceType::Unknown);
    }

    #[test]
    fn the_address_reached_is_listed_with_its_interface() {
        let list = services(Some("127.0.0.42".parse().expect("ip")), "rov");
        let reached = list
            .iter()
            .find(|s| s.ip == "127.0.0.42")
            .expect("the loopback alias is listed");
        assert_eq!(reached.interface_type, InterfaceType::Unknown);
        assert_eq!(reached.domain, "rov.local");
        assert!(list.iter().all(|s| s.service_type == "_http"));
        let json = serde_json::to_value(reached).expect("json");
        assert_eq!(json["interface_type"], "UNKNOWN");
        // Listed once, not again, when it is an interface's own address.
        let twice = services(Some("127.0.0.1".parse().expect("ip")), "rov");
        assert!(twice.iter().filter(|s| s.ip == "127.0.0.1").count() <= 1);
    }
}

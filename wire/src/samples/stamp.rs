//! The common header of every sensor sample: when it happened, how we know, which one.

crate::sample_struct! {
    /// When a sample's physical event happened and how that time was obtained.
    pub struct Stamp = "navsync.Stamp.v1" {
        /// Host time of the physical event, ns of the host's `CLOCK_MONOTONIC`.
        pub host_ns: i64,
        /// The device's own time of the event, ns in the device's time scale
        /// (counter ticks converted with the nominal tick length); 0 when `has_device_time` is 0.
        pub device_ns: i64,
        /// Per-source sequence number starting at 0; a gap means samples were dropped.
        pub seq: u64,
        /// How `host_ns` was obtained, a [`StampSource`] as `u8`.
        pub source: u8,
        /// 1 when `device_ns` holds the device's own time.
        pub has_device_time: u8,
        /// Reserved, zero.
        pub reserved: [u8; 6],
    }
}

/// How a host time stamp was obtained, from best to worst.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum StampSource {
    /// Not known.
    Unknown = 0,
    /// Kernel PPS time stamp (RFC 2783), taken in the interrupt handler.
    KernelPps = 1,
    /// A device counter mapped to host time by the clock model.
    DeviceCounter = 2,
    /// Kernel time stamp of the data-ready event (IIO timestamp channel).
    KernelEvent = 3,
    /// Host time at user-space wake-up on a modem-line change (TIOCMIWAIT).
    SerialLine = 4,
    /// Host time when the first byte was read (software sync; ms-level).
    Receipt = 5,
    /// Computed by the simulator from its oscillator model.
    Simulated = 6,
    /// Device time on the GNSS receiver's clock, less the receiver clock bias the tightly
    /// coupled filter estimates (GPS time), mapped to host time through the PPS clock model.
    ReceiverClock = 7,
}

impl StampSource {
    /// Decodes the `u8` stored in [`Stamp::source`].
    pub fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::KernelPps,
            2 => Self::DeviceCounter,
            3 => Self::KernelEvent,
            4 => Self::SerialLine,
            5 => Self::Receipt,
            6 => Self::Simulated,
            7 => Self::ReceiverClock,
            _ => Self::Unknown,
        }
    }

    /// Lower-case name for logs and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Unknown => "unknown",
            Self::KernelPps => "kernel-pps",
            Self::DeviceCounter => "device-counter",
            Self::KernelEvent => "kernel-event",
            Self::SerialLine => "serial-line",
            Self::Receipt => "receipt",
            Self::Simulated => "simulated",
            Self::ReceiverClock => "receiver-clock",
        }
    }
}

impl Stamp {
    /// A stamp with host time only.
    pub fn host(host_ns: i64, seq: u64, source: StampSource) -> Self {
        Self {
            host_ns,
            device_ns: 0,
            seq,
            source: source as u8,
            has_device_time: 0,
            reserved: [0; 6],
        }
    }

    /// A stamp with host and device time.
    pub fn with_device(host_ns: i64, device_ns: i64, seq: u64, source: StampSource) -> Self {
        Self {
            host_ns,
            device_ns,
            seq,
            source: source as u8,
            has_device_time: 1,
            reserved: [0; 6],
        }
    }

    /// The decoded stamp source.
    pub fn source(&self) -> StampSource {
        StampSource::from_u8(self.source)
    }
}

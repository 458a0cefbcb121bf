//! The fusion horizon's IMU buffer: the samples the delayed filter has not consumed yet, which
//! the output predictor replays to bring the delayed state to the present. Fixed capacity,
//! allocated once; no allocation per sample.

use nalgebra::Vector3;

/// One IMU interval as the filter uses it (body frame FRD, before bias compensation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuRecord {
    /// Host time of the end of the interval, ns.
    pub host_ns: i64,
    /// Interval length, s.
    pub dt_s: f64,
    /// Average angular rate over the interval, rad/s.
    pub gyro_rps: Vector3<f64>,
    /// Average specific force over the interval, m/s².
    pub accel_mps2: Vector3<f64>,
}

/// Capacity: 4 s at 2 kHz (the default 2 s horizon and the input order's hold, with room).
pub const CAPACITY: usize = 8192;

/// Ring buffer of [`ImuRecord`]s in time order.
#[derive(Debug, Clone)]
pub struct ImuBuffer {
    buf: Box<[ImuRecord]>,
    head: usize,
    len: usize,
    overflows: u64,
}

impl Default for ImuBuffer {
    fn default() -> Self {
        let zero = ImuRecord {
            host_ns: 0,
            dt_s: 0.0,
            gyro_rps: Vector3::zeros(),
            accel_mps2: Vector3::zeros(),
        };
        Self {
            buf: vec![zero; CAPACITY].into_boxed_slice(),
            head: 0,
            len: 0,
            overflows: 0,
        }
    }
}

impl ImuBuffer {
    /// Appends a record; when full, the oldest is dropped (and counted).
    pub fn push(&mut self, r: ImuRecord) {
        if self.len == CAPACITY {
            self.head = (self.head + 1) % CAPACITY;
            self.len -= 1;
            self.overflows += 1;
        }
        self.buf[(self.head + self.len) % CAPACITY] = r;
        self.len += 1;
    }

    /// The oldest record.
    pub fn front(&self) -> Option<&ImuRecord> {
        (self.len > 0).then(|| &self.buf[self.head])
    }

    /// Removes and returns the oldest record.
    pub fn pop(&mut self) -> Option<ImuRecord> {
        let r = *self.front()?;
        self.head = (self.head + 1) % CAPACITY;
        self.len -= 1;
        Some(r)
    }

    /// Records oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &ImuRecord> {
        (0..self.len).map(move |i| &self.buf[(self.head + i) % CAPACITY])
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Records dropped because the buffer was full.
    pub fn overflows(&self) -> u64 {
        self.overflows
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifo_order_and_overflow() {
        let mut b = ImuBuffer::default();
        let rec = |t| ImuRecord {
            host_ns: t,
            dt_s: 0.0,
            gyro_rps: Vector3::zeros(),
            accel_mps2: Vector3::zeros(),
        };
        for t in 0..(CAPACITY as i64 + 10) {
            b.push(rec(t));
        }
        assert_eq!((b.len(), b.overflows()), (CAPACITY, 10));
        assert_eq!(b.front().unwrap().host_ns, 10);
        assert_eq!(b.pop().unwrap().host_ns, 10);
        assert_eq!(b.iter().last().unwrap().host_ns, CAPACITY as i64 + 9);
    }
}

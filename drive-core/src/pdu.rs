//! Modbus PDUs: requests borrowed from the receive buffer, and exception codes.

/// Most registers one read may return (0x03, 0x04, read part of 0x17).
pub const MAX_READ: u16 = 125;
/// Most registers one 0x10 may write.
pub const MAX_WRITE: u16 = 123;
/// Most registers the write part of 0x17 may write.
pub const MAX_RW_WRITE: u16 = 121;

/// A Modbus exception code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exception {
    /// 01: the function (or diagnostics sub-function) is not supported.
    IllegalFunction,
    /// 02: an address in the request has no object, or cannot be accessed that way.
    IllegalDataAddress,
    /// 03: a value is out of range, or the request's quantities or lengths are wrong.
    IllegalDataValue,
    /// 04: the drive cannot carry out a valid request in its present state.
    ServerDeviceFailure,
    /// 03 as well: a write's byte count is not twice its quantity (a map may answer it with a
    /// code of its own).
    ByteCount,
    /// A code of another vendor's map.
    Vendor(u8),
}

impl Exception {
    /// The code sent on the wire.
    pub const fn code(self) -> u8 {
        match self {
            Exception::IllegalFunction => 1,
            Exception::IllegalDataAddress => 2,
            Exception::IllegalDataValue | Exception::ByteCount => 3,
            Exception::ServerDeviceFailure => 4,
            Exception::Vendor(c) => c,
        }
    }
}

/// Register values as they stand in a request: big-endian 16-bit words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Words<'a>(&'a [u8]);

impl<'a> Words<'a> {
    /// Words of `bytes`; a trailing odd byte is ignored.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }
    /// How many words.
    pub fn len(&self) -> usize {
        self.0.len() / 2
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Word `i`.
    pub fn get(&self, i: usize) -> Option<u16> {
        let pair = self.0.get(2 * i..2 * i + 2)?;
        Some(u16::from_be_bytes([*pair.first()?, *pair.get(1)?]))
    }
    /// The words in order.
    pub fn iter(&self) -> impl Iterator<Item = u16> + 'a {
        self.pairs().iter().map(|&p| u16::from_be_bytes(p))
    }
    /// The words as big-endian byte pairs: a slice, so that zipping it with another slice makes
    /// an indexed loop without bounds checks.
    pub fn pairs(&self) -> &'a [[u8; 2]] {
        self.0.as_chunks::<2>().0
    }
}

/// A request PDU, borrowing its data from the receive buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request<'a> {
    /// 0x03 read holding registers.
    ReadHolding {
        /// First register.
        addr: u16,
        /// How many (1..=125).
        qty: u16,
    },
    /// 0x04 read input registers (the same objects as 0x03).
    ReadInput {
        /// First register.
        addr: u16,
        /// How many (1..=125).
        qty: u16,
    },
    /// 0x06 write single register.
    WriteSingle {
        /// The register.
        addr: u16,
        /// Its new value.
        value: u16,
    },
    /// 0x10 write multiple registers.
    WriteMultiple {
        /// First register.
        addr: u16,
        /// The values (1..=123).
        values: Words<'a>,
    },
    /// 0x17 read/write multiple registers: the write is done before the read.
    ReadWrite {
        /// First register read.
        read_addr: u16,
        /// How many read (1..=125).
        read_qty: u16,
        /// First register written.
        write_addr: u16,
        /// The values written (1..=121).
        values: Words<'a>,
    },
    /// 0x08 diagnostics.
    Diagnostics {
        /// Sub-function.
        sub: u16,
        /// Its data.
        data: &'a [u8],
    },
    /// 0x15 write file record: an image's records ([`crate::update`]).
    WriteFileRecord {
        /// Its sub-requests, checked whole.
        records: FileRecords<'a>,
    },
    /// 0x2B / 0x0E read device identification.
    ReadDeviceId {
        /// 1 basic, 2 regular, 3 extended (stream), 4 one object.
        code: u8,
        /// First (or only) object id.
        object: u8,
    },
}

/// A decoder of request PDUs: [`Request::parse`], or a map's own ([`SubIndex::parse`]).
pub type Parser = fn(&[u8]) -> Result<Request<'_>, Exception>;

fn be16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(at)?, *b.get(at + 1)?]))
}

impl<'a> Request<'a> {
    /// Decodes a PDU (function code and data, no address or CRC).
    ///
    /// Unsupported functions are [`Exception::IllegalFunction`]; wrong lengths, byte counts or
    /// quantities are [`Exception::IllegalDataValue`], as the Modbus state diagrams order them.
    ///
    /// ```
    /// use drive_core::pdu::Request;
    /// use drive_core::Exception;
    /// assert_eq!(Request::parse(&[0x03, 0x60, 0x0C, 0x00, 0x02]),
    ///            Ok(Request::ReadHolding { addr: 0x600C, qty: 2 }));
    /// assert_eq!(Request::parse(&[0x03, 0x60, 0x0C, 0x00, 126]), Err(Exception::IllegalDataValue));
    /// assert_eq!(Request::parse(&[0x05, 0x00, 0x01, 0xFF, 0x00]), Err(Exception::IllegalFunction));
    /// ```
    pub fn parse(pdu: &'a [u8]) -> Result<Self, Exception> {
        use Exception::IllegalDataValue as Bad;
        let (&function, data) = pdu.split_first().ok_or(Exception::IllegalFunction)?;
        let word = |at| be16(data, at).ok_or(Bad);
        let fixed = |n: usize| if data.len() == n { Ok(()) } else { Err(Bad) };
        let read_qty = |q: u16| if read_quantity(q) { Ok(q) } else { Err(Bad) };
        match function {
            0x03 | 0x04 => {
                fixed(4)?;
                let (addr, qty) = (word(0)?, read_qty(word(2)?)?);
                Ok(if function == 0x03 { Request::ReadHolding { addr, qty } } else { Request::ReadInput { addr, qty } })
            }
            0x06 => {
                fixed(4)?;
                Ok(Request::WriteSingle { addr: word(0)?, value: word(2)? })
            }
            0x10 => {
                let (addr, qty) = (word(0)?, word(2)?);
                let values = counted(data, 4, qty, MAX_WRITE)?;
                Ok(Request::WriteMultiple { addr, values })
            }
            0x17 => {
                let (read_addr, read_qty) = (word(0)?, read_qty(word(2)?)?);
                let (write_addr, write_qty) = (word(4)?, word(6)?);
                let values = counted(data, 8, write_qty, MAX_RW_WRITE)?;
                Ok(Request::ReadWrite { read_addr, read_qty, write_addr, values })
            }
            0x08 => {
                let sub = word(0)?;
                let rest = data.get(2..).unwrap_or_default();
                Ok(Request::Diagnostics { sub, data: rest })
            }
            0x15 => Ok(Request::WriteFileRecord { records: FileRecords::parse(data)? }),
            0x2B => match data {
                [0x0E, code, object] => Ok(Request::ReadDeviceId { code: *code, object: *object }),
                [0x0E, ..] => Err(Bad),
                _ => Err(Exception::IllegalFunction),
            },
            _ => Err(Exception::IllegalFunction),
        }
    }

    /// The request of a PDU of the commonest shapes, a register read (0x03, 0x04) or write
    /// (0x06, 0x10), if it is one and well-formed: then what [`Request::parse`] makes of it;
    /// `None` for anything else, which `parse` decodes (or refuses). A slave tries it first,
    /// inlined: one match on the PDU's bytes.
    ///
    /// ```
    /// use drive_core::pdu::{Request, Words};
    /// assert_eq!(Request::short(&[0x03, 0x60, 0x0C, 0x00, 0x02]), Some(Request::ReadHolding { addr: 0x600C, qty: 2 }));
    /// assert_eq!(Request::short(&[0x03, 0x60, 0x0C, 0x00, 126]), None);
    /// let pdu = [0x10, 0x60, 0x08, 0x00, 0x01, 0x02, 0x00, 0x05];
    /// assert_eq!(Request::short(&pdu), Some(Request::WriteMultiple { addr: 0x6008, values: Words::new(&pdu[6..]) }));
    /// assert_eq!(Request::short(&[0x10, 0x60, 0x08, 0x00, 0x01, 0x02, 0x00]), None);
    /// ```
    #[inline(always)]
    pub fn short(pdu: &'a [u8]) -> Option<Self> {
        let (&[function, ah, al, bh, bl], rest) = pdu.split_first_chunk::<5>()?;
        let (addr, word) = (u16::from_be_bytes([ah, al]), u16::from_be_bytes([bh, bl]));
        match (function, rest) {
            (0x03, []) if read_quantity(word) => Some(Request::ReadHolding { addr, qty: word }),
            (0x04, []) if read_quantity(word) => Some(Request::ReadInput { addr, qty: word }),
            (0x06, []) => Some(Request::WriteSingle { addr, value: word }),
            (0x10, [count, values @ ..])
                if (1..=MAX_WRITE).contains(&word)
                    && usize::from(*count) == 2 * usize::from(word)
                    && values.len() == usize::from(*count) =>
            {
                Some(Request::WriteMultiple { addr, values: Words::new(values) })
            }
            _ => None,
        }
    }
}

/// How a map's register requests name a register by an index and a sub-index byte after it
/// (seed 003: `01 03 20 03 01 00 02` reads 2 registers from 0x2003 sub-index 1), declared as data
/// so that a slave decodes the commonest of them inline, as [`Request::short`] Modbus's: the
/// table's register numbers are keys, `(index - base) << bits | sub`; from `window` on, the
/// sub-index [`Keys::window_sub`] names the register at the index itself.
///
/// ```
/// use drive_core::pdu::{Keys, Request};
/// let keys = Keys { base: 0x2000, indexes: 0x100, bits: 4, window: 0x1000, window_sub: 0xFF, max: 16 };
/// assert_eq!(keys.register(0x2003, 1), Some(0x31));
/// assert_eq!(keys.index_of(0x31), (0x2003, 1));
/// assert_eq!(keys.register(0x600C, 0xFF), Some(0x600C));
/// assert_eq!(keys.register(0x2003, 16), None);
/// assert_eq!(keys.short(&[0x03, 0x20, 0x03, 0x01, 0x00, 0x02]), Some(Request::ReadHolding { addr: 0x31, qty: 2 }));
/// assert_eq!(keys.short(&[0x03, 0x20, 0x03, 0x01, 0x00, 17]), None);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Keys {
    /// The table's first index.
    pub base: u16,
    /// How many indexes from `base` the table has.
    pub indexes: u16,
    /// The sub-index's bits in a key: sub-indices `0..1 << bits` an index.
    pub bits: u8,
    /// The first index that is a register of its own (with [`Keys::window_sub`]); the keys lie
    /// below it.
    pub window: u16,
    /// The sub-index that names the register at the index.
    pub window_sub: u8,
    /// The most registers a request reads or writes.
    pub max: u16,
}

impl Keys {
    /// The register number that an index and sub-index name, if they name one.
    #[inline(always)]
    pub const fn register(&self, index: u16, sub: u8) -> Option<u16> {
        if sub == self.window_sub && index >= self.window {
            Some(index)
        } else if (sub as u32).wrapping_shr(self.bits as u32) == 0 && index.wrapping_sub(self.base) < self.indexes {
            Some(self.key(index, sub))
        } else {
            None
        }
    }

    /// The table key of an index and sub-index of the table.
    #[inline(always)]
    pub const fn key(&self, index: u16, sub: u8) -> u16 {
        index.wrapping_sub(self.base).wrapping_shl(self.bits as u32) | sub as u16
    }

    /// The index and sub-index of a table key.
    pub const fn index_of(&self, key: u16) -> (u16, u8) {
        let bits = self.bits as u32;
        (self.base.wrapping_add(key.wrapping_shr(bits)), (key & !u16::MAX.wrapping_shl(bits)) as u8)
    }

    /// The request of a well-formed register read (0x03), write (0x06) or block write (0x10) of
    /// registers that the keys name, at most [`Keys::max`]: what the map's own decoder makes of
    /// it; `None` for anything else, which that decoder decodes (or refuses).
    #[inline(always)]
    pub fn short<'a>(&self, pdu: &'a [u8]) -> Option<Request<'a>> {
        let (&[function, ih, il, sub, wh, wl], rest) = pdu.split_first_chunk::<6>()?;
        let (index, word) = (u16::from_be_bytes([ih, il]), u16::from_be_bytes([wh, wl]));
        let addr = self.register(index, sub)?;
        let quantity = word.wrapping_sub(1) < self.max;
        match (function, rest) {
            (0x03, []) if quantity => Some(Request::ReadHolding { addr, qty: word }),
            (0x06, []) => Some(Request::WriteSingle { addr, value: word }),
            (0x10, [count, values @ ..])
                if quantity && usize::from(*count) == 2 * usize::from(word) && values.len() == usize::from(*count) =>
            {
                Some(Request::WriteMultiple { addr, values: Words::new(values) })
            }
            _ => None,
        }
    }
}

/// How a map's requests name a register by an index and a sub-index byte after it (seed 003):
/// the map's register numbers are [`Keys`] below [`Keys::window`]; from it on, they are the
/// native map's registers (a sub-index the map gives them).
#[derive(Clone, Copy, Debug)]
pub struct SubIndex {
    /// Decodes a request PDU, its register as the map's register number.
    pub parse: Parser,
    /// How requests name the registers, from which a slave decodes the commonest inline.
    pub keys: Keys,
}

/// The sub-requests of a write file record (0x15), as they stand in the request after its byte
/// count: each a reference type 6, a file number (from 1), a record number (0-9999), a record
/// length in registers and that many registers; checked whole before any is taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileRecords<'a>(&'a [u8]);

/// One sub-request of a write file record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileRecord<'a> {
    /// The file number, 1 or more.
    pub file: u16,
    /// The first record (register) number, 0-9999.
    pub record: u16,
    /// The registers' bytes, high byte first.
    pub data: &'a [u8],
}

/// The last record number a file has (Modbus: 0x270F).
pub const MAX_RECORD: u16 = 9999;

/// A sub-request's head: reference type, file, record, length.
const RECORD_HEAD: usize = 7;

impl<'a> FileRecords<'a> {
    /// The sub-requests of the request data `data` (its byte count first), if well-formed: a byte
    /// count of 7-245 that is the rest's length, each sub-request of reference type 6, its file
    /// number not 0, its records within the file's 10 000 and its length not 0.
    ///
    /// ```
    /// use drive_core::pdu::{FileRecord, FileRecords};
    /// let data = [9, 6, 0, 1, 0, 2, 0, 1, 0xAB, 0xCD];
    /// let records = FileRecords::parse(&data).unwrap();
    /// assert_eq!(records.iter().collect::<Vec<_>>(), [FileRecord { file: 1, record: 2, data: &[0xAB, 0xCD] }]);
    /// assert!(FileRecords::parse(&[9, 5, 0, 1, 0, 2, 0, 1, 0xAB, 0xCD]).is_err(), "reference type 5");
    /// assert!(FileRecords::parse(&[9, 6, 0, 0, 0, 2, 0, 1, 0xAB, 0xCD]).is_err(), "file 0");
    /// assert!(FileRecords::parse(&[9, 6, 0, 1, 0x27, 0x10, 0, 1, 0xAB, 0xCD]).is_err(), "record 10000");
    /// assert!(FileRecords::parse(&[10, 6, 0, 1, 0, 2, 0, 1, 0xAB, 0xCD]).is_err(), "byte count");
    /// ```
    pub fn parse(data: &'a [u8]) -> Result<Self, Exception> {
        let (&count, rest) = data.split_first().ok_or(Exception::IllegalDataValue)?;
        if !(9..=0xFB).contains(&count) || usize::from(count) != rest.len() {
            return Err(Exception::IllegalDataValue);
        }
        let mut left = rest;
        while !left.is_empty() {
            let (head, tail) = left.split_first_chunk::<RECORD_HEAD>().ok_or(Exception::IllegalDataValue)?;
            let [kind, fh, fl, rh, rl, lh, ll] = *head;
            let (file, record, len) =
                (u16::from_be_bytes([fh, fl]), u16::from_be_bytes([rh, rl]), u16::from_be_bytes([lh, ll]));
            let end = u32::from(record) + u32::from(len);
            if kind != 6 || file == 0 || len == 0 || end > u32::from(MAX_RECORD) + 1 {
                return Err(Exception::IllegalDataAddress);
            }
            left = tail.get(2 * usize::from(len)..).ok_or(Exception::IllegalDataValue)?;
        }
        Ok(Self(rest))
    }

    /// The sub-requests in order.
    pub fn iter(&self) -> impl Iterator<Item = FileRecord<'a>> + 'a {
        let mut left = self.0;
        core::iter::from_fn(move || {
            let (head, tail) = left.split_first_chunk::<RECORD_HEAD>()?;
            let [_, fh, fl, rh, rl, lh, ll] = *head;
            let n = 2 * usize::from(u16::from_be_bytes([lh, ll]));
            let data = tail.get(..n)?;
            left = tail.get(n..)?;
            Some(FileRecord { file: u16::from_be_bytes([fh, fl]), record: u16::from_be_bytes([rh, rl]), data })
        })
    }

    /// The request's data after its byte count, as received: what the reply echoes.
    pub fn bytes(&self) -> &'a [u8] {
        self.0
    }
}

/// Whether a read may ask for `qty` registers.
const fn read_quantity(qty: u16) -> bool {
    qty >= 1 && qty <= MAX_READ
}

/// The values of a write request whose quantity sits before a byte count at `at`.
fn counted(data: &[u8], at: usize, qty: u16, max: u16) -> Result<Words<'_>, Exception> {
    let count = *data.get(at).ok_or(Exception::IllegalDataValue)?;
    let values = data.get(at + 1..).unwrap_or_default();
    if !(1..=max).contains(&qty) {
        return Err(Exception::IllegalDataValue);
    }
    if usize::from(count) != 2 * usize::from(qty) || values.len() != usize::from(count) {
        return Err(Exception::ByteCount);
    }
    Ok(Words::new(values))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PDUs of every function code, with addresses and words at their edges and tails of
    /// every sort (none, byte counts right and wrong, values short, long and exact): `short` is
    /// `parse`'s request for the shapes it knows, `None` for the rest.
    #[test]
    fn short_is_parse_for_its_shapes() {
        let words = [0u16, 1, 2, 3, 122, 123, 124, 125, 126, 0x600C, 0xFFFF];
        let mut tails: heapless::Vec<heapless::Vec<u8, 256>, 64> = heapless::Vec::new();
        let _ = tails.push(heapless::Vec::new());
        for count in [0u8, 1, 2, 3, 4, 6, 246, 255] {
            for len in [0usize, 1, 2, 3, 4, 6, 246] {
                let mut tail = heapless::Vec::new();
                let _ = tail.push(count);
                let _ = tail.extend_from_slice([0xAB; 246].get(..len).unwrap_or_default());
                let _ = tails.push(tail);
            }
        }
        let mut short = 0;
        for function in 0..=u8::MAX {
            for addr in words {
                for word in words {
                    for tail in &tails {
                        let mut pdu: heapless::Vec<u8, 256> = heapless::Vec::new();
                        let _ = pdu.push(function);
                        let _ = pdu.extend_from_slice(&addr.to_be_bytes());
                        let _ = pdu.extend_from_slice(&word.to_be_bytes());
                        let _ = pdu.extend_from_slice(tail);
                        let parsed = Request::parse(&pdu);
                        let known = matches!(
                            parsed,
                            Ok(Request::ReadHolding { .. }
                                | Request::ReadInput { .. }
                                | Request::WriteSingle { .. }
                                | Request::WriteMultiple { .. })
                        );
                        assert_eq!(Request::short(&pdu), parsed.ok().filter(|_| known), "{pdu:02X?}");
                        short += usize::from(known);
                    }
                }
            }
        }
        assert!(short > 300, "{short} requests of the known shapes");
        assert_eq!(Request::short(&[0x03, 0, 0, 0]), None);
    }
}

//! The wire to one drive: tokio-modbus's RTU master over a serial port or the simulator's TCP
//! endpoint (raw RTU frames), and requests framed here where tokio-modbus has no master for them:
//! seed 003's sub-indexed requests, which no standard master frames, and Modbus ASCII lines
//! (tokio-modbus has no ASCII client). Those share one path above the framing: the request's PDU
//! is built once ([`Link::read`], [`Link::write`], [`Link::identify`]) and `Link::exchange`
//! frames it as RTU (CRC, a reply ended by t3.5 of silence) or ASCII (`:`, hex, LRC, CR LF, a
//! reply ended by its LF), then checks the reply's address and function and maps exceptions.

use std::borrow::Cow;
use std::fmt;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::{Instant, timeout, timeout_at};
use tokio_modbus::client::{Client, Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{ExceptionCode, ReadCode, Request, Slave, SlaveContext};

use crate::dict::{Address, Map};

/// Where the bus is.
#[derive(Clone, Debug)]
pub enum Target {
    /// The simulator's TCP endpoint (`HOST:PORT`), raw frames (RTU, or ASCII lines).
    Tcp(String),
    /// A serial port at a baud rate and parity.
    Serial {
        /// The port (`/dev/ttyUSB0`).
        port: String,
        /// Its settings.
        format: LineFormat,
    },
}

/// The parity bit of each character (the drive's 0x2100).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Parity {
    /// No parity bit (8N1, the factory's).
    #[default]
    None,
    /// Even parity (8E1).
    Even,
    /// Odd parity (8O1).
    Odd,
}

impl Parity {
    /// Every parity: none, even, odd.
    pub const ALL: [Parity; 3] = [Parity::None, Parity::Even, Parity::Odd];

    /// The parity named `none`, `even` or `odd`.
    pub fn from_name(name: &str) -> Option<Parity> {
        match name {
            "none" => Some(Parity::None),
            "even" => Some(Parity::Even),
            "odd" => Some(Parity::Odd),
            _ => None,
        }
    }
}

/// A serial line's settings: baud rate and parity, with 8 data bits and 1 stop bit (the drive's
/// formats are 8N1, 8E1 and 8O1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LineFormat {
    /// Bits a second.
    pub baud: u32,
    /// The parity.
    pub parity: Parity,
}

impl LineFormat {
    /// Bits a character takes on the wire: start, 8 data, parity if any, stop.
    pub fn bits_per_char(&self) -> u32 {
        if self.parity == Parity::None { 10 } else { 11 }
    }

    /// How long `chars` characters take on the wire.
    pub fn chars_time(&self, chars: u32) -> Duration {
        Duration::from_micros(
            u64::from(chars) * u64::from(self.bits_per_char()) * 1_000_000 / u64::from(self.baud.max(1)),
        )
    }

    /// Every setting a drive takes (0x202A's rates, 0x2100's parities), rate by rate.
    pub fn every() -> impl Iterator<Item = LineFormat> {
        drive_core::Baud::SUPPORTED
            .into_iter()
            .flat_map(|baud| Parity::ALL.into_iter().map(move |parity| LineFormat { baud, parity }))
    }
}

impl Default for LineFormat {
    /// The drive's factory settings: 9600 baud 8N1.
    fn default() -> Self {
        Self { baud: 9600, parity: Parity::None }
    }
}

impl fmt::Display for LineFormat {
    /// `38400 8E1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parity = match self.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        write!(f, "{} 8{parity}1", self.baud)
    }
}

/// How frames are delimited on the line (the drive's 0x2192 at its power-up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Framing {
    /// Modbus RTU: binary, a CRC, a frame ended by a silence (the factory's).
    #[default]
    Rtu,
    /// Modbus ASCII: a line of `:`, two hex digits a byte, the LRC, CR LF.
    Ascii,
}

/// Why a request failed.
#[derive(Debug)]
pub enum Error {
    /// The drive refused it with an exception.
    Refused {
        /// The exception code.
        code: u8,
        /// What the code means in the drive's map.
        meaning: String,
    },
    /// No answer in time.
    Timeout,
    /// The port or the connection failed, or a reply was malformed.
    Link(String),
    /// The command itself is wrong (an unknown name, a value that does not fit).
    Usage(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Refused { code, meaning } => write!(f, "refused by the drive (exception {code:02X}: {meaning})"),
            Error::Timeout => write!(f, "no answer from the drive in time"),
            Error::Link(why) => write!(f, "link: {why}"),
            Error::Usage(why) => write!(f, "{why}"),
        }
    }
}

impl std::error::Error for Error {}

/// What an exception code means in `map`: the reasons the map answers with it.
pub fn meaning(map: Map, code: u8) -> String {
    use drive_core::maps::layout::Exceptions;
    let codes = map.layout().map_or(Exceptions::MODBUS, |l| l.exceptions);
    let reasons = [
        (codes.function, "the drive does not serve this function"),
        (codes.unknown, "no such register"),
        (codes.read_only, "read-only register"),
        (codes.write_only, "write-only register"),
        (codes.out_of_range, "value out of range"),
        (codes.byte_count, "malformed request"),
        (codes.split, "half of a 32-bit value written alone"),
        (codes.busy, "busy: the axis moves, a run or a save is under way"),
        (codes.disabled, "the power stage is off"),
        (codes.faulted, "a latched fault or stop must be cleared first"),
        (codes.not_now, "not in the present mode or state"),
        (codes.infeasible, "no trajectory within the limits"),
        (codes.unsupported, "the drive does not do this"),
    ];
    let mut out: Vec<&str> = Vec::new();
    for (e, why) in reasons {
        if e.code() == code && !out.contains(&why) {
            out.push(why);
        }
    }
    if out.is_empty() { format!("code {code} is not one of the {} map's", map.name()) } else { out.join("; or ") }
}

/// A byte stream to the bus.
trait Stream: AsyncRead + AsyncWrite + Unpin + Send {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send> Stream for T {}

/// How requests are framed.
enum Io {
    /// tokio-modbus's RTU master.
    Modbus(Context),
    /// Our own frames in this framing (seed 003's sub-indexed requests in RTU; every request in
    /// ASCII).
    Raw(Box<dyn Stream>, Framing),
}

/// The identification strings of function 0x2B / 0x0E, objects 0-6.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Identity {
    /// Objects 0x00-0x06 (vendor, product code, revision, URL, product, model, application).
    pub objects: Vec<(u8, String)>,
}

impl Identity {
    /// Object `id`'s text, empty if absent.
    pub fn object(&self, id: u8) -> &str {
        self.objects.iter().find(|(i, _)| *i == id).map_or("", |(_, s)| s.as_str())
    }
}

/// A connection to the drive at one slave address, with the map it answers with.
pub struct Link {
    target: Target,
    slave: u8,
    io: Io,
    /// How long a request may take, answer included.
    pub limit: Duration,
    /// The map the drive answers with.
    pub map: Map,
}

async fn open(target: &Target) -> Result<Box<dyn Stream>, Error> {
    let (stream, baud): (Box<dyn Stream>, u32) = match target {
        Target::Tcp(at) => {
            let s = tokio::net::TcpStream::connect(at).await.map_err(|e| Error::Link(format!("{at}: {e}")))?;
            // A request must not wait for the ACK of an earlier piece (Nagle's algorithm).
            s.set_nodelay(true).map_err(|e| Error::Link(e.to_string()))?;
            (Box::new(s), 115_200)
        }
        Target::Serial { port, format } => {
            let parity = match format.parity {
                Parity::None => tokio_serial::Parity::None,
                Parity::Even => tokio_serial::Parity::Even,
                Parity::Odd => tokio_serial::Parity::Odd,
            };
            let s = tokio_serial::SerialStream::open(&tokio_serial::new(port, format.baud).parity(parity))
                .map_err(|e| Error::Link(format!("{port}: {e}")))?;
            (Box::new(s), format.baud)
        }
    };
    Ok(Box::new(framed(stream, t15(baud))))
}

/// The stream with what it receives handed on in frames: bytes gathered until a silence of
/// `gap`. A UART (and QEMU's) delivers a reply byte by byte, and tokio-modbus 0.17's RTU
/// decoder loses its place on a device identification reply of which it has seen two bytes;
/// a whole frame it always takes.
fn framed(stream: Box<dyn Stream>, gap: Duration) -> tokio::io::DuplexStream {
    let (ours, theirs) = tokio::io::duplex(1024);
    let (mut line_rx, mut line_tx) = tokio::io::split(stream);
    let (mut pipe_rx, mut pipe_tx) = tokio::io::split(ours);
    // When the link is dropped the writer sees the pipe's end and tells the reader, so that the
    // port or the connection closes (a serial port opens once; the simulator serves one
    // connection at a time).
    let closed = std::sync::Arc::new(tokio::sync::Notify::new());
    let closing = std::sync::Arc::clone(&closed);
    tokio::spawn(async move {
        let mut buf = vec![0u8; 512];
        loop {
            let first = tokio::select! {
                r = line_rx.read(&mut buf) => r,
                () = closed.notified() => return,
            };
            let mut n = match first {
                Ok(0) | Err(_) => return,
                Ok(n) => n,
            };
            while n < buf.len() {
                match timeout(gap, line_rx.read(buf.get_mut(n..).unwrap_or_default())).await {
                    Ok(Ok(m)) if m > 0 => n += m,
                    _ => break,
                }
            }
            if pipe_tx.write_all(buf.get(..n).unwrap_or_default()).await.is_err() {
                return;
            }
        }
    });
    tokio::spawn(async move {
        let _ = tokio::io::copy(&mut pipe_rx, &mut line_tx).await;
        closing.notify_one();
    });
    theirs
}

/// The silence inside a frame's gathering: 1.5 characters of 11 bits at `baud`, at least 3 ms
/// (the host's scheduling and QEMU's pace).
pub(crate) fn t15(baud: u32) -> Duration {
    Duration::from_micros(16_500_000 / u64::from(baud.max(1200))).max(Duration::from_millis(3))
}

/// The silence that ends a frame at `baud`: 3.5 characters of 11 bits, at least 1.75 ms, with
/// a margin for the host's scheduling.
fn t35(baud: u32) -> Duration {
    let chars = Duration::from_micros(38_500_000 / u64::from(baud.max(1200)));
    chars.max(Duration::from_micros(1750)) + Duration::from_millis(2)
}

/// A tokio-modbus request's answer within `limit`, an exception in `map`'s words.
async fn answered<T>(
    limit: Duration,
    map: Map,
    request: impl std::future::Future<Output = tokio_modbus::Result<T>>,
) -> Result<T, Error> {
    let answer = timeout(limit, request).await.map_err(|_| Error::Timeout)?.map_err(|e| Error::Link(e.to_string()))?;
    answer.map_err(|e: ExceptionCode| {
        let code = u8::from(e);
        Error::Refused { code, meaning: meaning(map, code) }
    })
}

impl Link {
    /// Connects to slave `slave` on `target` in RTU framing, answering with `map` (or, if
    /// `None`, the map its identification names).
    pub async fn connect(target: Target, slave: u8, map: Option<Map>, limit: Duration) -> Result<Self, Error> {
        Self::connect_with(target, Framing::Rtu, slave, map, limit).await
    }

    /// Connects to slave `slave` on `target` in `framing`, answering with `map` (or, if `None`,
    /// the map its identification names).
    pub async fn connect_with(
        target: Target,
        framing: Framing,
        slave: u8,
        map: Option<Map>,
        limit: Duration,
    ) -> Result<Self, Error> {
        let stream = open(&target).await?;
        let io = match framing {
            Framing::Rtu => Io::Modbus(rtu::attach_slave(stream, Slave(slave))),
            Framing::Ascii => Io::Raw(stream, Framing::Ascii),
        };
        let mut link = Self { target, slave, io, limit, map: map.unwrap_or(Map::Native) };
        if map.is_none() {
            let id = link.identify().await?;
            link.map = Map::from_application_name(id.object(6));
        }
        if link.map.sub_indexed() && matches!(link.io, Io::Modbus(_)) {
            // Drop tokio-modbus's stream before opening ours: a serial port opens once.
            link.io = Io::Raw(Box::new(tokio::io::empty()), Framing::Rtu);
            link.io = Io::Raw(reopen(&link.target).await?, Framing::Rtu);
        }
        Ok(link)
    }

    /// A link to no drive in particular ([`Link::set_slave`] chooses), answering with the native
    /// map, that frames every request itself: for a scan, whose requests drain what a late reply
    /// left and check whose reply came. The port may be one a dropped link still holds.
    pub async fn connect_raw(target: Target, framing: Framing, limit: Duration) -> Result<Self, Error> {
        let io = Io::Raw(reopen(&target).await?, framing);
        Ok(Self { target, slave: 0, io, limit, map: Map::Native })
    }

    /// The framing of the link.
    pub fn framing(&self) -> Framing {
        match self.io {
            Io::Modbus(_) => Framing::Rtu,
            Io::Raw(_, framing) => framing,
        }
    }

    /// The line's settings: the serial port's, or over TCP the simulator's nominal 115 200 8N1.
    pub fn line_format(&self) -> LineFormat {
        match &self.target {
            Target::Serial { format, .. } => *format,
            Target::Tcp(_) => LineFormat { baud: 115_200, parity: Parity::None },
        }
    }

    /// The slave address.
    pub fn slave(&self) -> u8 {
        self.slave
    }

    /// Talks to slave `slave` from now on (tokio-modbus framing only).
    pub fn set_slave(&mut self, slave: u8) {
        self.slave = slave;
        if let Io::Modbus(ctx) = &mut self.io {
            ctx.set_slave(Slave(slave));
        }
    }

    /// Asks the drive to echo two bytes (diagnostics 0x08, sub-function 0x0000, return query
    /// data): the shortest request every map serves (the EC-57's parser passes 0x08 through as
    /// Modbus has it), 8 bytes each way in RTU. A refusal ([`Error::Refused`]) is an answer too.
    pub async fn probe(&mut self) -> Result<(), Error> {
        // Sub-function 0, then the two bytes to echo.
        const DATA: [u8; 4] = [0x00, 0x00, 0x4F, 0x53];
        let (limit, map) = (self.limit, self.map);
        match &mut self.io {
            Io::Modbus(ctx) => {
                answered(limit, map, ctx.call(Request::Custom(0x08, Cow::Borrowed(&DATA)))).await.map(|_| ())
            }
            Io::Raw(..) => self.exchange(&[&[0x08][..], &DATA].concat()).await.map(|_| ()),
        }
    }

    /// The device identification (0x2B / 0x0E, regular category, from object 0).
    pub async fn identify(&mut self) -> Result<Identity, Error> {
        let limit = self.limit;
        let Io::Modbus(ctx) = &mut self.io else {
            return self.identify_raw().await;
        };
        let id = answered(limit, self.map, ctx.read_device_identification(ReadCode::Regular, 0)).await?;
        Ok(Identity {
            objects: id
                .device_id_objects
                .iter()
                .map(|o| (o.id, String::from_utf8_lossy(&o.value).into_owned()))
                .collect(),
        })
    }

    async fn identify_raw(&mut self) -> Result<Identity, Error> {
        // Read device identification, the regular category, from object 0.
        let reply = self.exchange(&[0x2B, 0x0E, 0x02, 0x00]).await?;
        // 2B 0E code conformity more next count, then (id, len, bytes)...
        let mut objects = Vec::new();
        let mut rest = reply.get(7..).unwrap_or_default();
        while let [id, len, tail @ ..] = rest {
            let n = usize::from(*len);
            let Some(value) = tail.get(..n) else { break };
            objects.push((*id, String::from_utf8_lossy(value).into_owned()));
            rest = tail.get(n..).unwrap_or_default();
        }
        Ok(Identity { objects })
    }

    /// Reads `n` registers at `at`.
    pub async fn read(&mut self, at: Address, n: u16) -> Result<Vec<u16>, Error> {
        let (limit, map) = (self.limit, self.map);
        match (&mut self.io, at.sub) {
            (Io::Modbus(ctx), None) => answered(limit, map, ctx.read_holding_registers(at.register, n)).await,
            _ => {
                let mut pdu = vec![0x03];
                pdu.extend_from_slice(&at.register.to_be_bytes());
                pdu.extend(at.sub);
                pdu.extend_from_slice(&n.to_be_bytes());
                let reply = self.exchange(&pdu).await?;
                let data = reply.get(2..).unwrap_or_default();
                if reply.get(1).copied() != Some(2 * n as u8) || data.len() != 2 * usize::from(n) {
                    return Err(Error::Link(format!("a read of {n} registers answered with {reply:02X?}")));
                }
                Ok(data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect())
            }
        }
    }

    /// Writes `values` from `at`: one register with 0x06, more with 0x10.
    pub async fn write(&mut self, at: Address, values: &[u16]) -> Result<(), Error> {
        let (limit, map) = (self.limit, self.map);
        match (&mut self.io, at.sub, values) {
            (Io::Modbus(ctx), None, [v]) => answered(limit, map, ctx.write_single_register(at.register, *v)).await,
            (Io::Modbus(ctx), None, _) => answered(limit, map, ctx.write_multiple_registers(at.register, values)).await,
            (_, sub, values) => {
                let mut pdu = vec![if values.len() == 1 { 0x06 } else { 0x10 }];
                pdu.extend_from_slice(&at.register.to_be_bytes());
                pdu.extend(sub);
                if values.len() != 1 {
                    pdu.extend_from_slice(&(values.len() as u16).to_be_bytes());
                    pdu.push(2 * values.len() as u8);
                }
                for v in values {
                    pdu.extend_from_slice(&v.to_be_bytes());
                }
                self.exchange(&pdu).await.map(|_| ())
            }
        }
    }

    /// Sends `pdu` in a frame of our own, RTU or ASCII as the link is framed, and returns the
    /// reply's PDU (an exception as an error): on a link that frames its requests itself
    /// ([`Link::connect_raw`], a sub-indexed map's, an ASCII link), for a function tokio-modbus
    /// does not decode (0x15).
    pub async fn exchange(&mut self, pdu: &[u8]) -> Result<Vec<u8>, Error> {
        let (limit, slave, map) = (self.limit, self.slave, self.map);
        let baud = match &self.target {
            Target::Serial { format, .. } => format.baud,
            Target::Tcp(_) => 115_200,
        };
        // A link to a sub-indexed map or an ASCII link is opened raw (`Link::connect_with`).
        let Io::Raw(stream, framing) = &mut self.io else {
            return Err(Error::Usage("a sub-indexed address on a map without sub-indices".into()));
        };
        let Some(&function) = pdu.first() else { return Err(Error::Usage("an empty request".into())) };
        // What came after a reply's time was up belongs to no request.
        drain(stream).await;
        let mut adu = vec![slave];
        adu.extend_from_slice(pdu);
        let deadline = Instant::now() + limit;
        let reply = match framing {
            Framing::Rtu => rtu_exchange(stream, &adu, deadline, t35(baud)).await?,
            Framing::Ascii => ascii_exchange(stream, &adu, deadline).await?,
        };
        match reply.as_slice() {
            [a, ..] if *a != slave => Err(Error::Link(format!("a reply from address {a} to a request to {slave}"))),
            [_, f, code] if *f == function | 0x80 => Err(Error::Refused { code: *code, meaning: meaning(map, *code) }),
            [_, f, ..] if *f == function => Ok(reply.get(1..).unwrap_or_default().to_vec()),
            _ => Err(Error::Link(format!("a malformed reply {reply:02X?} to function {function:02X}"))),
        }
    }
}

/// Opens `target`, retrying a moment: a serial port opens once, and a link dropped just before
/// closes it only once its framing tasks see the pipe's end.
async fn reopen(target: &Target) -> Result<Box<dyn Stream>, Error> {
    let mut tries = 0;
    loop {
        tokio::task::yield_now().await;
        match open(target).await {
            Ok(s) => return Ok(s),
            Err(_) if tries < 25 => tries += 1,
            Err(e) => return Err(e),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Reads and drops whatever the stream holds now.
async fn drain(stream: &mut Box<dyn Stream>) {
    let mut buf = [0u8; 256];
    while let Ok(Ok(n)) = timeout(Duration::ZERO, stream.read(&mut buf)).await {
        if n == 0 {
            break;
        }
    }
}

/// Sends `adu` (address, PDU) as an RTU frame and returns the reply's ADU, its CRC checked and
/// dropped: the reply is whole when the line falls silent for `t35` after its first byte.
async fn rtu_exchange(
    stream: &mut Box<dyn Stream>,
    adu: &[u8],
    deadline: Instant,
    t35: Duration,
) -> Result<Vec<u8>, Error> {
    let mut frame = adu.to_vec();
    let crc = drive_core::crc::crc16(&frame);
    frame.extend_from_slice(&crc.to_le_bytes());
    stream.write_all(&frame).await.map_err(|e| Error::Link(e.to_string()))?;
    let mut reply = Vec::new();
    let mut buf = [0u8; 256];
    loop {
        let wait = if reply.is_empty() {
            timeout_at(deadline, stream.read(&mut buf)).await
        } else {
            timeout(t35, stream.read(&mut buf)).await
        };
        match wait {
            Ok(Ok(0)) => return Err(Error::Link("connection closed".into())),
            Ok(Ok(n)) => reply.extend_from_slice(buf.get(..n).unwrap_or_default()),
            Ok(Err(e)) => return Err(Error::Link(e.to_string())),
            Err(_) if reply.is_empty() => return Err(Error::Timeout),
            Err(_) => break,
        }
    }
    if !drive_core::crc::frame_ok(&reply) {
        return Err(Error::Link(format!("a malformed reply {reply:02X?}")));
    }
    reply.truncate(reply.len() - 2);
    Ok(reply)
}

/// The Modbus ASCII line of `adu` (address, PDU): `:`, two upper-case hex digits a byte, the
/// LRC (the two's complement of the bytes' sum), CR LF.
pub fn ascii_line(adu: &[u8]) -> Vec<u8> {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let lrc = adu.iter().fold(0u8, |s, b| s.wrapping_add(*b)).wrapping_neg();
    let mut line = vec![b':'];
    for b in adu.iter().chain([lrc].iter()) {
        line.push(HEX[usize::from(b >> 4)]);
        line.push(HEX[usize::from(b & 0xF)]);
    }
    line.extend_from_slice(b"\r\n");
    line
}

/// The ADU (address, PDU) a Modbus ASCII line carries, its LRC checked and dropped: `line` is
/// what follows the `:` up to its LF. Hex digits of either case.
pub fn ascii_adu(line: &[u8]) -> Result<Vec<u8>, String> {
    let shown = || String::from_utf8_lossy(line).trim_end().to_string();
    let digits = line
        .strip_suffix(b"\n")
        .and_then(|l| l.strip_suffix(b"\r"))
        .ok_or_else(|| format!("a reply line {:?} not ended by CR LF", shown()))?;
    let (pairs, odd) = digits.as_chunks::<2>();
    if !odd.is_empty() || pairs.len() < 3 {
        return Err(format!("a reply line {:?} of an odd or too small number of digits", shown()));
    }
    let hex = |c: u8| char::from(c).to_digit(16).map(|d| d as u8);
    let mut bytes = Vec::with_capacity(pairs.len());
    for [h, l] in pairs {
        let (Some(h), Some(l)) = (hex(*h), hex(*l)) else {
            return Err(format!("a reply line {:?} with a character that is no hex digit", shown()));
        };
        bytes.push(h << 4 | l);
    }
    if bytes.iter().fold(0u8, |s, b| s.wrapping_add(*b)) != 0 {
        return Err(format!("a reply line {:?} with a bad LRC", shown()));
    }
    bytes.pop();
    Ok(bytes)
}

/// Sends `adu` (address, PDU) as a Modbus ASCII line and returns the reply's ADU, its LRC
/// checked and dropped: the first line for the same address and function (with or without
/// the exception bit) that ends by `deadline`. Lines for others, and anything outside a line,
/// are passed over.
async fn ascii_exchange(stream: &mut Box<dyn Stream>, adu: &[u8], deadline: Instant) -> Result<Vec<u8>, Error> {
    stream.write_all(&ascii_line(adu)).await.map_err(|e| Error::Link(e.to_string()))?;
    let ours = |reply: &[u8]| match (reply, adu) {
        ([a, f, ..], [slave, function, ..]) => a == slave && f & 0x7F == *function,
        _ => false,
    };
    let mut pending: Vec<u8> = Vec::new();
    let mut buf = [0u8; 256];
    loop {
        while let Some(lf) = pending.iter().position(|&b| b == b'\n') {
            let line: Vec<u8> = pending.drain(..=lf).collect();
            // A `:` starts a line wherever it comes: the last one's.
            let Some(colon) = line.iter().rposition(|&b| b == b':') else { continue };
            let reply = ascii_adu(line.get(colon + 1..).unwrap_or_default()).map_err(Error::Link)?;
            if ours(&reply) {
                return Ok(reply);
            }
        }
        match timeout_at(deadline, stream.read(&mut buf)).await {
            Ok(Ok(0)) => return Err(Error::Link("connection closed".into())),
            Ok(Ok(n)) => pending.extend_from_slice(buf.get(..n).unwrap_or_default()),
            Ok(Err(e)) => return Err(Error::Link(e.to_string())),
            Err(_) if pending.contains(&b':') => {
                let line = String::from_utf8_lossy(&pending).into_owned();
                return Err(Error::Link(format!("a reply line {line:?} unfinished in time")));
            }
            Err(_) => return Err(Error::Timeout),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ascii_line_is_hex_and_its_lrc() {
        // docs/modbus.md: a read of 2 registers from 0x0200 of node 1.
        assert_eq!(ascii_line(&[0x01, 0x03, 0x02, 0x00, 0x00, 0x02]), b":010302000002F8\r\n");
        let mut line = [0u8; drive_core::ascii::MAX_LINE];
        let adu = [0x11, 0x10, 0x06, 0x00, 0x00, 0x02, 0x04, 0x0C, 0x80, 0x00, 0x00];
        let n = drive_core::ascii::encode(&adu, &mut line).expect("encodes");
        assert_eq!(ascii_line(&adu), line.get(..n).expect("line"), "as the drive encodes it");
    }

    #[test]
    fn an_ascii_reply_is_checked() {
        assert_eq!(ascii_adu(b"0103020258A0\r\n"), Ok(vec![0x01, 0x03, 0x02, 0x02, 0x58]));
        assert_eq!(ascii_adu(b"0103020258a0\r\n"), Ok(vec![0x01, 0x03, 0x02, 0x02, 0x58]), "lower case");
        assert!(ascii_adu(b"0103020258A1\r\n").is_err_and(|e| e.contains("LRC")));
        assert!(ascii_adu(b"0103020258A\r\n").is_err_and(|e| e.contains("odd")));
        assert!(ascii_adu(b"01030202G8A0\r\n").is_err_and(|e| e.contains("hex")));
        assert!(ascii_adu(b"0103020258A0\n").is_err_and(|e| e.contains("CR LF")));
        assert!(ascii_adu(b"01FF\r\n").is_err());
    }

    /// A link to a fake ASCII slave on the other end of a pipe, which answers each request line
    /// with `answer(request ADU)`: raw bytes.
    fn fake(answer: impl Fn(&[u8]) -> Vec<u8> + Send + 'static) -> Link {
        let (ours, theirs) = tokio::io::duplex(1024);
        tokio::spawn(async move {
            let (mut rx, mut tx) = tokio::io::split(theirs);
            let mut line = Vec::new();
            let mut byte = [0u8; 1];
            while rx.read_exact(&mut byte).await.is_ok() {
                line.push(byte[0]);
                if byte[0] == b'\n' {
                    let adu = ascii_adu(line.get(1..).unwrap_or_default()).expect("a good request line");
                    if tx.write_all(&answer(&adu)).await.is_err() {
                        return;
                    }
                    line.clear();
                }
            }
        });
        Link {
            target: Target::Tcp("pipe".into()),
            slave: 1,
            io: Io::Raw(Box::new(ours), Framing::Ascii),
            limit: Duration::from_millis(300),
            map: Map::Servo,
        }
    }

    #[tokio::test(flavor = "current_thread")]
    async fn the_ascii_exchange_reads_writes_and_maps_exceptions() {
        let mut link = fake(|adu| match adu {
            // A read of 0130h: noise, another node's line, then ours in lower case.
            [1, 0x03, 0x01, 0x30, 0, 2] => {
                let mut out = b"junk\r\n".to_vec();
                out.extend(ascii_line(&[2, 0x03, 2, 0, 9]));
                out.extend(ascii_line(&[1, 0x03, 4, 0x02, 0x58, 0x00, 0x01]).to_ascii_lowercase());
                out
            }
            // A write of one register: the echo.
            [1, 0x06, ..] => ascii_line(adu),
            // 0x10: 02, no such register.
            [1, 0x10, ..] => ascii_line(&[1, 0x90, 0x02]),
            // A reply with a bad LRC.
            [1, 0x03, 0x05, ..] => b":01030200019A\r\n".to_vec(),
            _ => Vec::new(),
        });
        assert_eq!(link.framing(), Framing::Ascii);
        let at = |register| Address { register, sub: None };
        assert_eq!(link.read(at(0x0130), 2).await.expect("read"), [0x0258, 0x0001]);
        link.write(at(0x0130), &[300]).await.expect("write");
        let refused = link.write(at(0x0000), &[1, 2]).await.expect_err("refused");
        assert!(
            matches!(refused, Error::Refused { code: 2, ref meaning } if meaning.contains("no such register")),
            "{refused}"
        );
        assert!(matches!(link.read(at(0x0500), 1).await, Err(Error::Link(ref e)) if e.contains("LRC")));
        assert!(matches!(link.read(at(0x0600), 1).await, Err(Error::Timeout)), "no answer");
    }
}

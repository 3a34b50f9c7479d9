//! `magic station`: the host end of the deployable firmware's line protocol, over a serial port
//! (a board on `/dev/ttyUSB0`) or TCP (`tcp:HOST:PORT`: QEMU's `-serial tcp::PORT,server`).
//!
//! The protocol (the firmware's `serve` module and README): every line sent gets exactly one
//! answer line, in order — a day line `<id>,<result>` (the id of the model that inverted it), a
//! model line `model,…`, a command `status,…` — and lines starting with `!` come unasked: `!ready`
//! after the board started, `!model,error,…` when it abandoned an upload, `!error,…`.
//!
//! The station sends ahead of the answers as long as the unanswered lines fit the board's
//! receive buffer (`rx=` of its status), so the link is kept busy without flow control. When the
//! board restarts (`!ready`: a watchdog reset, a power cut) the lines in flight are gone: the
//! station resynchronises (`!status`), sends the day lines among them again (once: a day on which
//! the board restarts twice is reported, not retried forever), and reports the other lines as
//! lost.
//!
//! Serial ports are opened with the `serialport` crate (default features off: no libudev, which
//! only lists ports): one code path for Linux, macOS and the Windows laptops many observatories
//! use, 115 200 baud, 8 data bits, no parity, one stop bit, no flow control.

use crate::data::records::{self, ObsRow};
use anyhow::{anyhow, bail, Context, Result};
use magic_core::Model;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::Duration;

/// The serial line speed (the firmware's `uart::BAUD`).
pub const BAUD: u32 = 115_200;
/// Model bytes per upload line (`:` and 128 hex digits).
pub const UPLOAD_BYTES_PER_LINE: usize = 64;
/// How long the station waits for an answer before it gives up on the board.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(15);

/// The link to a board: lines out, lines in (read by a thread of their own, so that answers are
/// taken while the station sends ahead).
pub struct Link {
    out: Box<dyn Write + Send>,
    lines: Receiver<std::io::Result<String>>,
    name: String,
    /// Tells the reader thread to stop (it checks at each read timeout of a serial port).
    stop: Arc<AtomicBool>,
    /// A TCP link's socket, shut down on drop (which ends the reader thread's blocking read and
    /// frees QEMU's single-client serial port for the next station).
    socket: Option<TcpStream>,
}

impl Link {
    /// Opens `tcp:HOST:PORT` or a serial device (`/dev/ttyUSB0`, `COM3`).
    pub fn open(port: &str) -> Result<Link> {
        if let Some(addr) = port.strip_prefix("tcp:") {
            let s = TcpStream::connect(addr).with_context(|| format!("connecting to {port}"))?;
            return Link::tcp(s, port);
        }
        let p = serialport::new(port, BAUD)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(Duration::from_secs(1))
            .open()
            .with_context(|| format!("opening the serial port {port}"))?;
        let r = p.try_clone().context("cloning the serial port handle")?;
        Ok(Link::new(r, p, port))
    }

    /// A link over a connected TCP socket.
    pub fn tcp(s: TcpStream, name: &str) -> Result<Link> {
        s.set_nodelay(true)?;
        let mut link = Link::new(s.try_clone()?, s.try_clone()?, name);
        link.socket = Some(s);
        Ok(link)
    }

    /// A link over any byte streams (`name` for messages).
    pub fn new(
        reader: impl Read + Send + 'static,
        writer: impl Write + Send + 'static,
        name: &str,
    ) -> Link {
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        std::thread::spawn(move || {
            let mut r = BufReader::new(reader);
            let mut buf = Vec::new();
            loop {
                if stopped.load(Ordering::Relaxed) {
                    return;
                }
                match r.read_until(b'\n', &mut buf) {
                    Ok(0) => return,
                    Ok(_) if buf.last() == Some(&b'\n') => {
                        let line = String::from_utf8_lossy(&buf);
                        let line = line.trim_end_matches(['\n', '\r']).to_string();
                        buf.clear();
                        if tx.send(Ok(line)).is_err() {
                            return;
                        }
                    }
                    // (A serial port's read timeout: the bytes read so far stay in `buf`.)
                    Ok(_) => {}
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                        ) => {}
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        return;
                    }
                }
            }
        });
        Link {
            out: Box::new(writer),
            lines: rx,
            name: name.to_string(),
            stop,
            socket: None,
        }
    }

    fn send(&mut self, line: &str) -> Result<()> {
        let mut b = Vec::with_capacity(line.len() + 1);
        b.extend_from_slice(line.as_bytes());
        b.push(b'\n');
        self.out
            .write_all(&b)
            .and_then(|()| self.out.flush())
            .with_context(|| format!("writing to {}", self.name))
    }

    fn recv(&self, timeout: Duration) -> Result<String> {
        match self.lines.recv_timeout(timeout) {
            Ok(Ok(line)) => Ok(line),
            Ok(Err(e)) => Err(anyhow!("reading from {}: {e}", self.name)),
            Err(RecvTimeoutError::Timeout) => Err(anyhow!(
                "no answer from the board on {} within {} s",
                self.name,
                timeout.as_secs()
            )),
            Err(RecvTimeoutError::Disconnected) => {
                Err(anyhow!("the link to the board ({}) closed", self.name))
            }
        }
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(s) = &self.socket {
            let _ = s.shutdown(std::net::Shutdown::Both);
        }
    }
}

/// The board's state, from its `status,…` answer or `!ready,…` line.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoardStatus {
    /// Id (CRC-32) of the running model, if any.
    pub model: Option<u32>,
    /// Its slot.
    pub slot: Option<usize>,
    /// Why the board last started (`power-on`, `command`, `watchdog`, `fault`, `other`).
    pub reset: String,
    /// Bytes of receive buffer: the most the station sends ahead of the answers.
    pub rx: usize,
    /// The largest model a slot holds, bytes.
    pub slot_bytes: usize,
    /// Whether every result line carries the variables' standard deviations too (`sd=yes`: a
    /// firmware built with the feature `sd`).
    pub sd: bool,
    /// Every `key=value` field as sent.
    pub fields: Vec<(String, String)>,
}

impl BoardStatus {
    /// Reads a `status,…` or `!ready,…` line.
    pub fn parse(line: &str) -> Option<BoardStatus> {
        let rest = line
            .strip_prefix("status,")
            .or_else(|| line.strip_prefix("!ready,"))?;
        let fields: Vec<(String, String)> = rest
            .split(',')
            .filter_map(|f| f.split_once('='))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let get = |k: &str| fields.iter().find(|f| f.0 == k).map(|f| f.1.as_str());
        let num = |k: &str| get(k).and_then(|v| v.parse::<usize>().ok());
        Some(BoardStatus {
            model: get("model").and_then(|v| u32::from_str_radix(v, 16).ok()),
            slot: num("slot"),
            reset: get("reset").unwrap_or("").to_string(),
            rx: num("rx")?,
            slot_bytes: num("slot_bytes").unwrap_or(0),
            sd: get("sd") == Some("yes"),
            fields,
        })
    }
}

/// What the station sends.
#[derive(Clone, Debug)]
pub enum Item {
    /// A day line (sent again after a board restart).
    Day(String),
    /// Any other line: a command or an upload line (not sent again).
    Line(String),
    /// Wait until every line sent is answered, then this long.
    Pause(Duration),
}

/// The answer to an item.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// The board's answer line.
    Board(String),
    /// The board restarted while the line was in flight, and it was not (or no longer) sent again.
    Lost,
}

/// A line the board sent unasked.
#[derive(Clone, Debug)]
pub enum Event {
    /// The board started (`!ready`).
    Restarted(Option<BoardStatus>),
    /// The board abandoned an upload (`!model,error,…`).
    UploadAbandoned(String),
    /// Any other `!` line (`!error,…`).
    Other(String),
}

/// What a [`Station::run`] got back.
#[derive(Debug, Default)]
pub struct Transcript {
    /// The answer to each item (`None` for pauses).
    pub answers: Vec<Option<Answer>>,
    /// Unasked lines, each with the index of the first item not yet answered when it came.
    pub events: Vec<(usize, Event)>,
}

/// A connected board.
pub struct Station {
    link: Link,
    /// The board's state as last reported.
    pub status: BoardStatus,
    /// How long to wait for an answer.
    pub timeout: Duration,
}

impl Station {
    /// Asks the board for its status (`!status`); lines before its answer (a start-up line,
    /// answers to an earlier station's lines) are skipped.
    pub fn connect(link: Link) -> Result<Station> {
        let mut st = Station {
            link,
            status: BoardStatus::default(),
            timeout: ANSWER_TIMEOUT,
        };
        st.status = st.resync()?;
        Ok(st)
    }

    fn resync(&mut self) -> Result<BoardStatus> {
        self.link.send("!status")?;
        loop {
            let line = self.link.recv(self.timeout)?;
            if line.starts_with("status,") {
                return BoardStatus::parse(&line)
                    .ok_or_else(|| anyhow!("cannot read the board's status line: {line}"));
            }
        }
    }

    /// Sends `items` and collects one answer per line, sending ahead as far as the board's
    /// receive buffer allows.
    pub fn run(&mut self, items: &[Item]) -> Result<Transcript> {
        let mut t = Transcript {
            answers: vec![None; items.len()],
            events: Vec::new(),
        };
        let mut queue: VecDeque<usize> = (0..items.len()).collect();
        let mut inflight: VecDeque<(usize, usize)> = VecDeque::new();
        let mut bytes = 0usize;
        let mut restarts = vec![0u8; items.len()];
        loop {
            while let Some(&i) = queue.front() {
                match &items[i] {
                    Item::Pause(d) => {
                        if !inflight.is_empty() {
                            break;
                        }
                        queue.pop_front();
                        std::thread::sleep(*d);
                    }
                    Item::Day(s) | Item::Line(s) => {
                        let n = s.len() + 1;
                        if !inflight.is_empty() && bytes + n > self.status.rx.max(1) {
                            break;
                        }
                        self.link.send(s)?;
                        queue.pop_front();
                        inflight.push_back((i, n));
                        bytes += n;
                    }
                }
            }
            if inflight.is_empty() {
                if queue.is_empty() {
                    return Ok(t);
                }
                continue;
            }
            let line = self.link.recv(self.timeout)?;
            let at = inflight.front().map_or(items.len(), |f| f.0);
            if line.starts_with("!ready") {
                t.events
                    .push((at, Event::Restarted(BoardStatus::parse(&line))));
                self.status = self.resync()?;
                // The lines in flight are gone: days go again (once), the rest is lost.
                for (i, _) in inflight.drain(..).rev() {
                    restarts[i] = restarts[i].saturating_add(1);
                    if matches!(items[i], Item::Day(_)) && restarts[i] < 2 {
                        queue.push_front(i);
                    } else {
                        t.answers[i] = Some(Answer::Lost);
                    }
                }
                bytes = 0;
            } else if line.starts_with("!model,") {
                t.events.push((at, Event::UploadAbandoned(line)));
            } else if line.starts_with("!error,input overrun") {
                // Bytes of the lines in flight were lost: answers no longer match lines.
                bail!("the board lost input ({line}); the station sent more than rx= ahead");
            } else if line.starts_with('!') {
                t.events.push((at, Event::Other(line)));
            } else {
                let (i, n) = inflight
                    .pop_front()
                    .ok_or_else(|| anyhow!("the board sent a line nobody asked for: {line}"))?;
                bytes -= n;
                t.answers[i] = Some(Answer::Board(line));
            }
        }
    }

    /// Resets the board (`!reset`) and waits for it to start again; returns its start-up status.
    pub fn reset(&mut self) -> Result<BoardStatus> {
        match self.run(&[Item::Line("!reset".into())])?.answers.first() {
            Some(Some(Answer::Board(a))) if a == "reset" => {}
            other => bail!("the board did not take !reset: {other:?}"),
        }
        loop {
            let line = self.link.recv(self.timeout)?;
            if line.starts_with("!ready,") {
                self.status = BoardStatus::parse(&line)
                    .ok_or_else(|| anyhow!("cannot read the board's start-up line: {line}"))?;
                return Ok(self.status.clone());
            }
        }
    }

    /// Uploads a model file and checks that the board switched to it; returns its id.
    pub fn upload(&mut self, model: &[u8]) -> Result<u32> {
        let id = model_id(model).ok_or_else(|| anyhow!("not a model file: too short"))?;
        let items: Vec<Item> = upload_lines(model).into_iter().map(Item::Line).collect();
        let t = self.run(&items)?;
        if let Some((_, e)) = t.events.first() {
            bail!("the upload did not complete: {e:?}");
        }
        for a in &t.answers {
            match a {
                Some(Answer::Board(l)) if l.starts_with("model,error,") => {
                    bail!(
                        "the board refused the model: {}",
                        &l["model,error,".len()..]
                    )
                }
                Some(Answer::Board(_)) => {}
                _ => bail!("the upload did not complete: a line was lost"),
            }
        }
        let want = format!("model,ok,{id:08x}");
        match t.answers.last() {
            Some(Some(Answer::Board(l))) if *l == want => {}
            other => bail!("the board did not confirm the model ({other:?}, expected {want})"),
        }
        self.status.model = Some(id);
        Ok(id)
    }
}

/// The id of a model file: its last four bytes, the CRC-32 of everything before them (what the
/// board names on every answer).
pub fn model_id(bytes: &[u8]) -> Option<u32> {
    let tail: [u8; 4] = bytes.get(bytes.len().checked_sub(4)?..)?.try_into().ok()?;
    Some(u32::from_le_bytes(tail))
}

/// The lines that upload a model: `!model <size> <id>`, then `:<hex>` lines of
/// [`UPLOAD_BYTES_PER_LINE`] bytes.
///
/// ```
/// let mut model = vec![0u8; 70];
/// model[66..].copy_from_slice(&0x7921_866bu32.to_le_bytes()); // its CRC-32, the id
/// let lines = magic_train::firmware::station::upload_lines(&model);
/// assert_eq!(lines[0], "!model 70 7921866b");
/// assert_eq!(lines.len(), 3); // 64 bytes, then 6
/// assert_eq!(lines[2], ":00006b862179");
/// ```
pub fn upload_lines(model: &[u8]) -> Vec<String> {
    let id = model_id(model).unwrap_or(0);
    let mut lines = vec![format!("!model {} {id:08x}", model.len())];
    for chunk in model.chunks(UPLOAD_BYTES_PER_LINE) {
        let mut l = String::with_capacity(1 + 2 * chunk.len());
        l.push(':');
        for b in chunk {
            l.push_str(&format!("{b:02x}"));
        }
        lines.push(l);
    }
    lines
}

/// Splits a day answer `<id>,<result>` into the model id and the result line (as `magic invert`
/// writes it); `None` for `none,…` (no model) or a line of another kind.
///
/// ```
/// use magic_train::firmware::station::split_answer;
/// let a = "7921866b,2.580113,0.893687,11.237006,-0.559353,1.808878,0,4095";
/// assert_eq!(split_answer(a).map(|(id, _)| id), Some(0x7921_866b));
/// assert_eq!(split_answer("none,error,no model: upload one with !model"), None);
/// ```
pub fn split_answer(line: &str) -> Option<(u32, &str)> {
    let (id, rest) = line.split_once(',')?;
    if id.len() != 8 {
        return None;
    }
    Some((u32::from_str_radix(id, 16).ok()?, rest))
}

/// The day lines of observation rows (the firmware's format, as `magic qemu` sends them); `None`
/// for rows the host already rejected (they are not sent: their error names file, line and
/// column).
pub fn day_lines(rows: &[ObsRow], with_date: bool) -> Vec<Option<String>> {
    let text = records::firmware_lines(rows, with_date);
    rows.iter()
        .zip(text.lines())
        .map(|(r, l)| r.obs.is_ok().then(|| l.to_string()))
        .collect()
}

/// `magic station`'s options.
pub struct Options {
    /// `tcp:HOST:PORT` or a serial device.
    pub port: String,
    /// A model file to run (uploaded unless the board runs it already); needed with `days`.
    pub model: Option<PathBuf>,
    /// Observation CSV, as for `magic invert`.
    pub days: Option<PathBuf>,
    /// Result CSV (standard output without it).
    pub output: Option<PathBuf>,
    /// The days hold standardised values.
    pub standardized: bool,
}

/// `magic station`: connects, uploads the model if the board does not run it, streams the days
/// and writes one result row per input row: `[date,]model,<magic invert's columns>`.
pub fn run_cli(o: &Options) -> Result<()> {
    let mut st = Station::connect(Link::open(&o.port)?)?;
    eprintln!(
        "board on {}: model {}, reset {}, {} bytes per slot",
        o.port,
        st.status
            .model
            .map_or("none".to_string(), |m| format!("{m:08x}")),
        st.status.reset,
        st.status.slot_bytes
    );
    let Some(model_path) = &o.model else {
        if o.days.is_some() {
            bail!("--days needs --model: the model names the columns and is checked against the board's");
        }
        return Ok(());
    };
    let bytes = std::fs::read(model_path)
        .with_context(|| format!("{}: cannot read model file", model_path.display()))?;
    let model = Model::decode(&bytes).map_err(|e| anyhow!("{}: {e}", model_path.display()))?;
    let id = model_id(&bytes).unwrap_or(0);
    if st.status.model == Some(id) {
        eprintln!("the board runs {id:08x} already");
    } else {
        if st.status.slot_bytes > 0 && bytes.len() > st.status.slot_bytes {
            bail!(
                "{}: {} bytes, a model slot on the board holds {}: export an int8 model (`magic export`)",
                model_path.display(),
                bytes.len(),
                st.status.slot_bytes
            );
        }
        st.upload(&bytes)
            .with_context(|| format!("uploading {}", model_path.display()))?;
        eprintln!(
            "uploaded {} ({} bytes): the board runs {id:08x}",
            model_path.display(),
            bytes.len()
        );
    }
    let Some(days) = &o.days else {
        return Ok(());
    };
    let rows = records::read_obs(days, &model, o.standardized)?;
    let lines = day_lines(&rows, model.needs_time());
    let items: Vec<Item> = lines.iter().flatten().cloned().map(Item::Day).collect();
    let t = st.run(&items)?;
    for (at, e) in &t.events {
        eprintln!("board, before day {at} of the stream: {e:?}");
    }
    let mut answers = t.answers.into_iter();
    let text = output_rows(&model, &rows, &lines, &mut answers, st.status.sd);
    match &o.output {
        Some(p) => {
            std::fs::write(p, &text).with_context(|| format!("{}: cannot write", p.display()))?
        }
        None => print!("{text}"),
    }
    let bad = text
        .lines()
        .skip(1)
        .filter(|l| l.contains(",error,"))
        .count();
    eprintln!(
        "{} rows -> {}",
        rows.len(),
        o.output
            .as_deref()
            .map_or("standard output".into(), |p| p.display().to_string())
    );
    if bad > 0 {
        bail!(
            "{bad} of {} rows could not be inverted (error rows written)",
            rows.len()
        );
    }
    Ok(())
}

/// The result CSV: a header, then one row per input row: the date (if the input has one), the
/// model id, and the result as `magic invert` writes it (host-side errors as `magic invert`
/// writes them, with an empty model). With `sd` (the board says `sd=yes`) the header names the
/// standard deviations' columns too, as `magic invert --sd` writes them.
fn output_rows(
    model: &Model<'_>,
    rows: &[ObsRow],
    lines: &[Option<String>],
    answers: &mut impl Iterator<Item = Option<Answer>>,
    sd: bool,
) -> String {
    let with_date = rows.iter().any(|r| r.date.is_some());
    let mut text = String::new();
    if with_date {
        text.push_str("date,");
    }
    text.push_str("model,");
    text.push_str(&records::result_header(model, false));
    if sd {
        for c in records::sd_columns(model) {
            text.push(',');
            text.push_str(&c);
        }
    }
    text.push('\n');
    for (row, line) in rows.iter().zip(lines) {
        if with_date {
            text.push_str(row.date.as_deref().unwrap_or(""));
            text.push(',');
        }
        let cell = match (&row.obs, line) {
            (Err(msg), _) => format!(",error,{}", msg.replace(',', ";")),
            (Ok(_), None) => ",error,not sent".to_string(),
            (Ok(_), Some(_)) => match answers.next().flatten() {
                Some(Answer::Board(a)) => a,
                Some(Answer::Lost) => ",error,the board restarted while inverting this row".into(),
                None => ",error,no answer".into(),
            },
        };
        text.push_str(&cell);
        text.push('\n');
    }
    text
}

/// Reads a station result CSV back: per data row, the model id (`None` when empty) and the
/// result as `magic invert` writes it.
pub fn read_output(path: &Path) -> Result<Vec<(Option<u32>, String)>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    let skip = usize::from(header.starts_with("date,"));
    Ok(lines
        .map(|l| {
            let mut it = l.splitn(skip + 2, ',');
            for _ in 0..skip {
                it.next();
            }
            let id = it.next().and_then(|v| u32::from_str_radix(v, 16).ok());
            (id, it.next().unwrap_or("").to_string())
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_lines_are_read() {
        let s = BoardStatus::parse(
            "!ready,model=7921866b,slot=0,reset=watchdog,rx=1024,slot_bytes=24576,flash=1",
        )
        .unwrap();
        assert_eq!(s.model, Some(0x7921_866b));
        assert_eq!(s.slot, Some(0));
        assert_eq!(s.reset, "watchdog");
        assert_eq!((s.rx, s.slot_bytes), (1024, 24576));
        let none = BoardStatus::parse("status,model=none,slot=none,reset=power-on,rx=512").unwrap();
        assert_eq!((none.model, none.slot, none.rx), (None, None, 512));
        assert!(!s.sd && !none.sd);
        let sd = BoardStatus::parse("status,model=none,rx=512,stack=10712,sd=yes").unwrap();
        assert!(sd.sd);
        assert!(BoardStatus::parse("model,ok,12345678").is_none());
    }

    #[test]
    fn uploads_are_hex_lines_named_by_the_model_crc() {
        let model: Vec<u8> = (0..150u32).map(|i| i as u8).collect();
        let lines = upload_lines(&model);
        let id = u32::from_le_bytes([146, 147, 148, 149]);
        assert_eq!(lines[0], format!("!model 150 {id:08x}"));
        assert_eq!(lines.len(), 1 + 3);
        assert_eq!(lines[1].len(), 1 + 2 * UPLOAD_BYTES_PER_LINE);
        let back: Vec<u8> = lines[1..]
            .iter()
            .flat_map(|l| {
                (1..l.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&l[i..i + 2], 16).unwrap())
                    .collect::<Vec<_>>()
            })
            .collect();
        assert_eq!(back, model);
    }

    #[test]
    fn answers_split_into_model_and_result() {
        assert_eq!(
            split_answer("7921866b,1.000000,2"),
            Some((0x7921_866b, "1.000000,2"))
        );
        assert_eq!(
            split_answer("0000000a,error,field 2: not a number"),
            Some((10, "error,field 2: not a number"))
        );
        assert_eq!(split_answer("none,error,no model"), None);
        assert_eq!(split_answer("model,ok,12345678"), None);
    }

    /// A scripted board on an in-memory link: answers each line with its number, restarts once.
    #[test]
    fn lines_in_flight_at_a_restart_are_sent_again_or_reported_lost() {
        use std::io::{Cursor, Read};
        struct Board {
            out: Cursor<Vec<u8>>,
        }
        impl Read for Board {
            fn read(&mut self, b: &mut [u8]) -> std::io::Result<usize> {
                self.out.read(b)
            }
        }
        // The board's side as the station will see it, given what it sends: the status answer,
        // answers to d0 and l1, a restart (d2 and l3 were in flight), the resync's status, then
        // answers to d2 (sent again).
        let script = "status,model=00000001,rx=4096\n\
                      00000001,a0\nmodel,x\n!ready,model=00000001,rx=4096,reset=watchdog\n\
                      status,model=00000001,rx=4096\n00000001,a2\n";
        let board = Board {
            out: Cursor::new(script.as_bytes().to_vec()),
        };
        let mut st = Station::connect(Link::new(board, std::io::sink(), "script")).unwrap();
        st.status.rx = 20; // room for two or three short lines in flight
        let items = vec![
            Item::Day("d0".into()),
            Item::Line("l1".into()),
            Item::Pause(Duration::ZERO),
            Item::Day("d2".into()),
            Item::Line("l3".into()),
        ];
        let t = st.run(&items).unwrap();
        assert_eq!(t.answers[0], Some(Answer::Board("00000001,a0".into())));
        assert_eq!(t.answers[1], Some(Answer::Board("model,x".into())));
        assert_eq!(t.answers[2], None);
        assert_eq!(t.answers[3], Some(Answer::Board("00000001,a2".into())));
        assert_eq!(t.answers[4], Some(Answer::Lost));
        assert!(matches!(t.events[0], (3, Event::Restarted(Some(_)))));
    }
}

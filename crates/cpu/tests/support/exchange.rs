//! Paper 2's frame exchange between the host and a capsule on its own thread, as a test of the
//! `RtCapsule` plug-in boundary: the host signals "host finished" (semaphore S1), the capsule thread
//! renders (ray generation, trace, shading, block D, block P) and signals "capsule finished" (S2)
//! with the frame, and the host merges it (block U). The CPU frame itself calls the capsule in line
//! (see `hybrid_cpu::capsule`): its raster needs the capsule's frame first.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

use hybrid_core::depth_merge::{CapsuleStats, PackedRtFrame};
use hybrid_cpu::capsule::{CapsuleRequest, RtCapsule};
use hybrid_scene::Camera;

/// An owned [`CapsuleRequest`], to cross to the capsule thread.
#[derive(Debug, Clone)]
pub struct OwnedCapsuleRequest {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    pub clip_depth: Option<Vec<f32>>,
}

impl OwnedCapsuleRequest {
    pub fn as_request(&self) -> CapsuleRequest<'_> {
        CapsuleRequest { camera: self.camera, width: self.width, height: self.height, clip_depth: self.clip_depth.as_deref() }
    }
}

/// Where the exchange stands (the paper's two semaphore pairs: S1 "host finished", S2 "capsule
/// finished"; each resets after it is consumed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExchangeState {
    /// Both semaphores in standby: the host owns the frame and may merge it or ask for the next.
    HostOwnsFrame,
    /// S1 signalled: the capsule is rendering; the host waits on S2.
    CapsuleRendering,
}

/// A misuse of the exchange or a capsule thread that died.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExchangeError {
    /// `host_finished` while the capsule is still rendering, or `wait_capsule_finished` with no
    /// frame requested.
    OutOfOrder(ExchangeState),
    /// The capsule thread has stopped (it panicked).
    CapsuleGone,
}

impl std::fmt::Display for ExchangeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::OutOfOrder(s) => write!(f, "frame exchange called out of order (state {s:?})"),
            Self::CapsuleGone => write!(f, "the RT capsule thread has stopped"),
        }
    }
}

impl std::error::Error for ExchangeError {}

enum HostSignal {
    /// S1: the host finished its frame; render this request into this (recycled) buffer.
    HostFinished(OwnedCapsuleRequest, PackedRtFrame),
    Stop,
}

/// The handshake with a capsule running on its own thread. Per frame:
/// `host_finished(request)` (S1) → capsule renders → `wait_capsule_finished()` (S2) returns the
/// frame → the host merges it → `recycle(frame)` returns the buffer for the next frame.
pub struct FrameExchange {
    to_capsule: Sender<HostSignal>,
    from_capsule: Receiver<(PackedRtFrame, CapsuleStats)>,
    thread: Option<JoinHandle<()>>,
    state: ExchangeState,
    spare: Option<PackedRtFrame>,
}

impl FrameExchange {
    /// Starts the capsule thread.
    pub fn spawn(mut capsule: Box<dyn RtCapsule>) -> std::io::Result<Self> {
        let (to_capsule, host_rx) = channel::<HostSignal>();
        let (capsule_tx, from_capsule) = channel();
        let thread = std::thread::Builder::new().name("rt-capsule".into()).spawn(move || {
            while let Ok(HostSignal::HostFinished(request, mut frame)) = host_rx.recv() {
                let stats = capsule.render(&request.as_request(), &mut frame);
                // S2: capsule finished.
                if capsule_tx.send((frame, stats)).is_err() {
                    break;
                }
            }
        })?;
        Ok(Self { to_capsule, from_capsule, thread: Some(thread), state: ExchangeState::HostOwnsFrame, spare: None })
    }

    pub fn state(&self) -> ExchangeState {
        self.state
    }

    /// Signals S1 (host finished): the capsule starts rendering `request`.
    pub fn host_finished(&mut self, request: OwnedCapsuleRequest) -> Result<(), ExchangeError> {
        if self.state != ExchangeState::HostOwnsFrame {
            return Err(ExchangeError::OutOfOrder(self.state));
        }
        let frame = self.spare.take().unwrap_or_else(|| PackedRtFrame::new(0, 0));
        self.to_capsule.send(HostSignal::HostFinished(request, frame)).map_err(|_| ExchangeError::CapsuleGone)?;
        self.state = ExchangeState::CapsuleRendering;
        Ok(())
    }

    /// Waits for S2 (capsule finished) and takes the packed frame.
    pub fn wait_capsule_finished(&mut self) -> Result<(PackedRtFrame, CapsuleStats), ExchangeError> {
        if self.state != ExchangeState::CapsuleRendering {
            return Err(ExchangeError::OutOfOrder(self.state));
        }
        let r = self.from_capsule.recv().map_err(|_| ExchangeError::CapsuleGone)?;
        self.state = ExchangeState::HostOwnsFrame;
        Ok(r)
    }

    /// Hands a merged frame's buffer back so the next frame reuses its allocation.
    pub fn recycle(&mut self, frame: PackedRtFrame) {
        self.spare = Some(frame);
    }
}

impl Drop for FrameExchange {
    fn drop(&mut self) {
        let _ = self.to_capsule.send(HostSignal::Stop);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

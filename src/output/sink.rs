//! Frame sinks: where the frames of a run go as they are made (a GIF, a VTK series, ...).
//!
//! A command's loop hands every frame to each of its sinks as a [`FrameView`] and closes them
//! with [`FrameSink::finish`]; a sink keeps what it wants of each frame. A simulation hands its
//! full state too ([`FrameSink::add_state`]: velocities, APIC matrices), which sinks that store
//! positions only ignore. [`Every`] passes on the start frame and every `k`-th step only, as
//! `--frame-every` and `--vtk-every` ask.

use anyhow::Result;
use phi_flip::RecordedFrame;

/// One frame of a run, with the frame before it and, for a rollout, the ground truth.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FrameView<'a> {
    /// The frame's index (a dataset frame for a rollout).
    pub frame: usize,
    /// The step that made it, counted from 1 (0 for the start frame).
    pub step: usize,
    /// The positions `[N, dim]` row-major.
    pub positions: &'a [f32],
    /// The positions of the frame before (the start frame's own for the start frame).
    pub before: &'a [f32],
    /// The true positions of this frame and of the frame before, when the run has a truth.
    pub truth: Option<(&'a [f32], &'a [f32])>,
}

/// Where a run's frames go.
pub(crate) trait FrameSink {
    /// Takes one frame.
    ///
    /// # Errors
    /// The sink's write errors, naming its file.
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()>;

    /// Takes one frame with the simulator's state on the host (`state.positions` are
    /// `frame.positions`); a sink that stores positions only takes it as [`FrameSink::add`].
    ///
    /// # Errors
    /// The sink's write errors, naming its file.
    fn add_state(&mut self, frame: &FrameView<'_>, state: &RecordedFrame) -> Result<()> {
        let _ = state;
        self.add(frame)
    }

    /// Closes the output (a GIF's trailer); a run that stops early closes its sinks too.
    ///
    /// # Errors
    /// The sink's write errors, naming its file.
    fn finish(self: Box<Self>) -> Result<()>;
}

/// A sink that passes on the start frame (step 0) and every `every`-th step.
#[derive(Debug)]
pub struct Every<S> {
    every: usize,
    sink: S,
}

impl<S> Every<S> {
    /// `sink` fed every `every`-th step (`every ≥ 1`; 0 is taken as 1).
    pub fn new(every: usize, sink: S) -> Self {
        Every {
            every: every.max(1),
            sink,
        }
    }
}

impl<S: FrameSink> FrameSink for Every<S> {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        if frame.step.is_multiple_of(self.every) {
            self.sink.add(frame)?;
        }
        Ok(())
    }

    fn add_state(&mut self, frame: &FrameView<'_>, state: &RecordedFrame) -> Result<()> {
        if frame.step.is_multiple_of(self.every) {
            self.sink.add_state(frame, state)?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<()> {
        Box::new(self.sink).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records the steps it is given and whether it was finished.
    struct Steps<'a>(&'a std::cell::RefCell<Vec<usize>>);

    impl FrameSink for Steps<'_> {
        fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
            self.0.borrow_mut().push(frame.step);
            Ok(())
        }

        fn finish(self: Box<Self>) -> Result<()> {
            self.0.borrow_mut().push(usize::MAX);
            Ok(())
        }
    }

    #[test]
    fn every_passes_the_start_frame_and_every_kth_step_then_finishes() {
        let seen = std::cell::RefCell::new(Vec::new());
        let mut sink: Box<dyn FrameSink + '_> = Box::new(Every::new(3, Steps(&seen)));
        let p = [0.0f32; 2];
        for step in 0..=7 {
            let view = FrameView {
                frame: 10 + step,
                step,
                positions: &p,
                before: &p,
                truth: None,
            };
            sink.add(&view).unwrap();
        }
        sink.finish().unwrap();
        assert_eq!(*seen.borrow(), vec![0, 3, 6, usize::MAX]);
    }

    /// Records the velocities of the states it is given.
    struct States<'a>(&'a std::cell::RefCell<Vec<(usize, Vec<f32>)>>);

    impl FrameSink for States<'_> {
        fn add(&mut self, _: &FrameView<'_>) -> Result<()> {
            anyhow::bail!("a state was expected")
        }

        fn add_state(&mut self, frame: &FrameView<'_>, state: &RecordedFrame) -> Result<()> {
            self.0
                .borrow_mut()
                .push((frame.step, state.velocities.clone()));
            Ok(())
        }

        fn finish(self: Box<Self>) -> Result<()> {
            Ok(())
        }
    }

    #[test]
    fn states_reach_the_sink_on_its_steps_and_positions_only_sinks_take_them_as_frames() {
        let seen = std::cell::RefCell::new(Vec::new());
        let steps = std::cell::RefCell::new(Vec::new());
        let mut sinks: Vec<Box<dyn FrameSink + '_>> = vec![
            Box::new(Every::new(2, States(&seen))),
            Box::new(Steps(&steps)),
        ];
        let p = [0.0f32; 2];
        for step in 0..=4 {
            let state = RecordedFrame {
                positions: p.to_vec(),
                velocities: vec![step as f32; 2],
                affine: None,
            };
            let view = FrameView {
                frame: step,
                step,
                positions: &p,
                before: &p,
                truth: None,
            };
            for sink in &mut sinks {
                sink.add_state(&view, &state).unwrap();
            }
        }
        let velocities = |v: f32| vec![v; 2];
        assert_eq!(
            *seen.borrow(),
            vec![
                (0, velocities(0.0)),
                (2, velocities(2.0)),
                (4, velocities(4.0))
            ]
        );
        assert_eq!(*steps.borrow(), vec![0, 1, 2, 3, 4]);
    }
}

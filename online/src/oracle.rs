//! Who answers the core's questions about the model. [`crate::core::LoopCore`] decides; an [`Oracle`]
//! evaluates the value, the certified-set membership, the domain and the control for the relative states
//! it asks about. [`crate::track_oracle::TrackOracle`] asks the fastrack service over one `Track` stream; a
//! process that holds the model itself (the simulator's in-process mode) answers with the server's own code
//! and no network.

use crate::core::{Answer, ModelView, Query};
use crate::online_loop::LoopError;
use fastrack_proto::planner_speed::SpeedRow;
use std::future::Future;

/// Answers [`Query`]s about one model.
pub trait Oracle {
    /// The model as the core reads it: its table, `Q`, its state size and the certificate horizon.
    fn view(&self) -> &ModelView;

    /// Answers one question: one [`Answer`] for a [`Query::Tick`], one per relative state for a
    /// [`Query::Batch`]. A tick whose `beta` the model would not choose for its `d_obs` (the table changed
    /// under the loop) fails with [`LoopError::TableMismatch`].
    fn answer<const D: usize>(
        &mut self,
        query: &Query<D>,
    ) -> impl Future<Output = Result<Vec<Answer>, LoopError>> + Send;

    /// The model's table as it stands now, read again after a [`LoopError::TableMismatch`].
    fn refresh(&mut self) -> impl Future<Output = Result<Vec<SpeedRow>, LoopError>> + Send;
}

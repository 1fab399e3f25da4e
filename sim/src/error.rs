//! Every way the simulator refuses input.

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    #[error("unknown setup name `{0}`: expected N.M_K (robots.machines_storages), e.g. 14.10_4")]
    BadSetupName(String),
    #[error("setup `{setup}` is invalid: {reason}")]
    BadSetup { setup: String, reason: String },
    #[error("setup `{setup}` does not fit in the {room} m room: {reason}")]
    DoesNotFit {
        setup: String,
        room: f32,
        reason: String,
    },
    #[error("config error in `{field}`: {reason}")]
    BadConfig { field: String, reason: String },
    #[error("could not parse config {source_name}: {message}")]
    ConfigParse {
        source_name: String,
        message: String,
    },
    #[error(transparent)]
    Input(#[from] inputs::InputError),
    #[error("command for robot {robot} is not finite: ({vx}, {vy})")]
    NonFiniteCommand { robot: u32, vx: f32, vy: f32 },
    #[error("expected {expected} commands (one per robot), got {got}")]
    WrongCommandCount { expected: usize, got: usize },
    #[error("action {action} for robot index {index} is not one of 0..5")]
    BadAction { index: usize, action: u8 },
    #[error("no {kind} with id {id}")]
    UnknownId { kind: &'static str, id: u32 },
    #[error("no free spot for a new {kind} after {tries} tries")]
    NoFreeSpot { kind: &'static str, tries: usize },
    #[error("position ({x}, {y}) for a new {kind} is outside the room or overlaps another body")]
    BadPosition { kind: &'static str, x: f32, y: f32 },
}

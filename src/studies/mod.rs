//! Studies: measurements that answer an inspector's questions with numbers (mask noise,
//! stability, the hierarchy's efficiency, the Gaussian budget), each with its rows, tables and
//! chart. Uses every layer below; `report` and everything beneath it never use this.

pub mod budget;
pub mod hierarchy;
pub mod mask_noise;
pub mod real;
pub mod segment;
pub mod stability;
pub mod update;

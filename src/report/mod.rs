//! Reports: charts and tables of measured results, as files. Presentation only.

pub mod study_chart;

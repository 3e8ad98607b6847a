//! The league's NAO rebuilt in rapier3d: the robot as data ([`model`]).

pub mod model;

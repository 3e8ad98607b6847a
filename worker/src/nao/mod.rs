//! The league's NAO rebuilt in rapier3d: the robot as data ([`model`]), its
//! forward kinematics ([`kinematics`]), its simulation ([`sim`]), the walk
//! engine ([`walk`]), one walking trial ([`trial`]) and its replay file
//! ([`replay`]).

pub mod kinematics;
pub mod model;
pub mod replay;
pub mod sim;
pub mod trial;
pub mod walk;

//! The league's NAO rebuilt in rapier3d: the robot as data ([`model`]), its
//! forward kinematics ([`kinematics`]), its simulation ([`sim`]), the walk
//! engine ([`walk`]) and one walking trial ([`trial`]).

pub mod kinematics;
pub mod model;
pub mod sim;
pub mod trial;
pub mod walk;

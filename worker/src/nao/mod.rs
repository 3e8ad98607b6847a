//! The league's NAO rebuilt in rapier3d: the robot as data ([`model`]), its
//! forward kinematics ([`kinematics`]), its simulation ([`sim`]), the walk
//! engine ([`walk`]) and its balance at the league's pace ([`balance`]), one walking trial ([`trial`]), what its feet
//! did with the distance ([`footwork`]) and its replay file ([`replay`]).

pub mod balance;
pub mod footwork;
pub mod kinematics;
pub mod model;
pub mod replay;
pub mod sim;
pub mod trial;
pub mod walk;

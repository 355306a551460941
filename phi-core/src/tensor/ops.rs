//! Arithmetic operators for [`Tensor`]: `+ - * /` between tensors (broadcasting) and with `f32`
//! scalars on either side, and unary `-`.
//!
//! Operators cannot return a `Result`, so a shape misfit panics, with the message of
//! [`Tensor::binary`]'s error and the caller's location.

use std::ops::{Add, Div, Mul, Neg, Sub};

use super::Tensor;
use crate::backend::{Backend, BinaryOp, UnaryOp};

macro_rules! binary_operator {
    ($trait:ident, $method:ident, $op:expr) => {
        impl<B: Backend> $trait<&Tensor<B>> for &Tensor<B> {
            type Output = Tensor<B>;
            #[track_caller]
            fn $method(self, rhs: &Tensor<B>) -> Tensor<B> {
                self.binary($op, rhs).unwrap_or_else(|e| panic!("{e}"))
            }
        }
        impl<B: Backend> $trait<Tensor<B>> for &Tensor<B> {
            type Output = Tensor<B>;
            #[track_caller]
            fn $method(self, rhs: Tensor<B>) -> Tensor<B> {
                self.$method(&rhs)
            }
        }
        impl<B: Backend> $trait<&Tensor<B>> for Tensor<B> {
            type Output = Tensor<B>;
            #[track_caller]
            fn $method(self, rhs: &Tensor<B>) -> Tensor<B> {
                (&self).$method(rhs)
            }
        }
        impl<B: Backend> $trait<Tensor<B>> for Tensor<B> {
            type Output = Tensor<B>;
            #[track_caller]
            fn $method(self, rhs: Tensor<B>) -> Tensor<B> {
                (&self).$method(&rhs)
            }
        }
        impl<B: Backend> $trait<f32> for &Tensor<B> {
            type Output = Tensor<B>;
            fn $method(self, rhs: f32) -> Tensor<B> {
                self.binary_scalar($op, rhs)
            }
        }
        impl<B: Backend> $trait<f32> for Tensor<B> {
            type Output = Tensor<B>;
            fn $method(self, rhs: f32) -> Tensor<B> {
                self.binary_scalar($op, rhs)
            }
        }
    };
}

binary_operator!(Add, add, BinaryOp::Add);
binary_operator!(Sub, sub, BinaryOp::Sub);
binary_operator!(Mul, mul, BinaryOp::Mul);
binary_operator!(Div, div, BinaryOp::Div);

// Scalars on the left: `2.0 * x`, `1.0 - x`, `1.0 / x`.
impl<B: Backend> Add<&Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn add(self, rhs: &Tensor<B>) -> Tensor<B> {
        rhs.binary_scalar(BinaryOp::Add, self)
    }
}
impl<B: Backend> Add<Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn add(self, rhs: Tensor<B>) -> Tensor<B> {
        self + &rhs
    }
}
impl<B: Backend> Mul<&Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn mul(self, rhs: &Tensor<B>) -> Tensor<B> {
        rhs.binary_scalar(BinaryOp::Mul, self)
    }
}
impl<B: Backend> Mul<Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn mul(self, rhs: Tensor<B>) -> Tensor<B> {
        self * &rhs
    }
}
impl<B: Backend> Sub<&Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn sub(self, rhs: &Tensor<B>) -> Tensor<B> {
        rhs.unary(UnaryOp::Neg).binary_scalar(BinaryOp::Add, self)
    }
}
impl<B: Backend> Sub<Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn sub(self, rhs: Tensor<B>) -> Tensor<B> {
        self - &rhs
    }
}
impl<B: Backend> Div<&Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn div(self, rhs: &Tensor<B>) -> Tensor<B> {
        rhs.recip().binary_scalar(BinaryOp::Mul, self)
    }
}
impl<B: Backend> Div<Tensor<B>> for f32 {
    type Output = Tensor<B>;
    fn div(self, rhs: Tensor<B>) -> Tensor<B> {
        self / &rhs
    }
}

impl<B: Backend> Neg for &Tensor<B> {
    type Output = Tensor<B>;
    fn neg(self) -> Tensor<B> {
        self.unary(UnaryOp::Neg)
    }
}
impl<B: Backend> Neg for Tensor<B> {
    type Output = Tensor<B>;
    fn neg(self) -> Tensor<B> {
        self.unary(UnaryOp::Neg)
    }
}

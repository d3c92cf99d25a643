//! Memory layouts of the layers' activations and how the kernels read them.
//!
//! Why a vertex-major layout: a sparse product gathers, for every vertex, the feature rows of its
//! neighbours. In `[B, V, C]` one neighbour's values are B runs of C values far apart, so every
//! call first copies its input to a vertex-major form and its output back (a fifth of a
//! Chebyshev convolution's time). A network that keeps its activations `[V, B, C]` throughout
//! gathers one contiguous block of B·C values per neighbour and never transposes a whole array.
//!
//! Inside the kernels every vertex's block is handled channel-major (`[C, B]`: the channel
//! mixing runs over the batch in SIMD lanes). A `[V, B, C]` block is transposed to that form in
//! cache, vertex by vertex; a `[V, C, B]` array (the kernels' own intermediates) is read as is.

use crate::kernel::{CHUNK_ROWS, Madd, Real, chunk_span, gather_row, load_chunk};
use rayon::prelude::*;

/// The array layouts the kernels read and write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Io {
    /// `[B, V, C]`.
    BatchMajor,
    /// `[V, B, C]`: the layers' `forward_vertex_major` layout.
    VertexBatch,
    /// `[V, C, B]`: the kernels' internal form.
    VertexChannel,
}

/// A vertex-major array (`[V, C, B]` or `[V, B, C]`) as the kernels read it: per vertex a
/// channel-major `[C, B]` block, borrowed or transposed on the fly.
#[derive(Clone, Copy)]
pub(crate) struct Blocks<'a, T> {
    data: &'a [T],
    batch: usize,
    c: usize,
    /// `[V, B, C]` (blocks need a transpose) rather than `[V, C, B]`.
    batch_channel: bool,
}

impl<'a, T: Real> Blocks<'a, T> {
    /// `data` in layout `io`, which must be vertex-major (`[B, V, C]` data is converted first,
    /// see [`to_channel_major`]).
    pub fn new(data: &'a [T], io: Io, batch: usize, c: usize) -> Self {
        debug_assert!(io != Io::BatchMajor);
        Self {
            data,
            batch,
            c,
            batch_channel: io == Io::VertexBatch,
        }
    }

    /// A `[V, C, B]` array.
    pub fn channel_major(data: &'a [T], batch: usize, c: usize) -> Self {
        Self::new(data, Io::VertexChannel, batch, c)
    }

    /// Values per vertex (B·C).
    #[inline(always)]
    pub fn n(&self) -> usize {
        self.batch * self.c
    }

    /// The blocks of vertices `i0 .. i0 + cnt` as channel-major `[cnt, C, B]`: borrowed, or
    /// transposed into `buf` (at least `cnt · n` long).
    #[inline(always)]
    pub fn chunk<'s>(self, i0: usize, cnt: usize, buf: &'s mut [T]) -> &'s [T]
    where
        'a: 's,
    {
        let n = self.n();
        let part = &self.data[i0 * n..][..cnt * n];
        if !self.batch_channel {
            return part;
        }
        let buf = &mut buf[..cnt * n];
        for (src, dst) in part.chunks_exact(n).zip(buf.chunks_exact_mut(n)) {
            T::transpose_block(src, self.batch, self.c, dst);
        }
        buf
    }

    /// acc = Σ_j vals_j · block_j over one matrix row (`cols`, `vals`), channel-major; `tmp`
    /// (n values) holds the `[B, C]` sum before its transpose.
    #[inline(always)]
    pub fn gather<M: Madd>(self, cols: &[u32], vals: &[T], tmp: &mut [T], acc: &mut [T]) {
        let n = self.n();
        if self.batch_channel {
            gather_row::<T, M>(cols, vals, self.data, n, tmp);
            T::transpose_block(tmp, self.batch, self.c, acc);
        } else {
            gather_row::<T, M>(cols, vals, self.data, n, acc);
        }
    }
}

/// `x` (layout `io`, V vertices × C channels × B) as a channel-major `[V, C, B]` copy in a
/// buffer of `ws`.
pub(crate) fn to_channel_major<T: Real>(
    x: &[T],
    io: Io,
    (batch, v, c): (usize, usize, usize),
    ws: &crate::workspace::Workspace,
) -> Vec<T> {
    let n = batch * c;
    let mut out = ws.take(v * n);
    if n == 0 {
        return out;
    }
    out.par_chunks_mut(CHUNK_ROWS * n)
        .enumerate()
        .for_each(|(chunk, o)| {
            let (i0, cnt) = chunk_span(chunk, v);
            match io {
                Io::BatchMajor => load_chunk(x, (batch, v, c), (i0, cnt), o),
                Io::VertexChannel => o.copy_from_slice(&x[i0 * n..][..cnt * n]),
                Io::VertexBatch => {
                    Blocks::new(x, io, batch, c).chunk(i0, cnt, o);
                }
            }
        });
    out
}

/// Where one chunk of vertices writes its results.
pub(crate) enum ChunkOut<'a, T> {
    /// Into a channel-major `[V, c, B]` array: the chunk's contiguous part.
    ChannelMajor(&'a mut [T]),
    /// Into a `[B, V, c]` array: the chunk's run of every batch slice.
    BatchMajor(Vec<&'a mut [T]>),
    /// Into a `[V, B, c]` array: the chunk's contiguous part, one transposed block per vertex.
    VertexBatch {
        out: &'a mut [T],
        batch: usize,
        c: usize,
    },
    /// Nowhere (the result is not wanted).
    Discard,
}

impl<T: Real> ChunkOut<'_, T> {
    pub fn is_discard(&self) -> bool {
        matches!(self, ChunkOut::Discard)
    }

    /// Stores the chunk's results, given as channel-major blocks `[cnt, c, B]`.
    #[inline(always)]
    pub fn store(&mut self, blocks: &[T]) {
        match self {
            ChunkOut::ChannelMajor(out) => out.copy_from_slice(&blocks[..out.len()]),
            ChunkOut::BatchMajor(runs) => T::scatter_runs(blocks, runs),
            ChunkOut::VertexBatch { out, batch, c } => {
                let n = *batch * *c;
                for (src, dst) in blocks.chunks_exact(n).zip(out.chunks_exact_mut(n)) {
                    T::transpose_block(src, *c, *batch, dst);
                }
            }
            ChunkOut::Discard => {}
        }
    }

    /// The chunk's own part of a channel-major output (results can be written in place).
    #[inline(always)]
    pub fn direct(&mut self) -> Option<&mut [T]> {
        match self {
            ChunkOut::ChannelMajor(out) => Some(out),
            _ => None,
        }
    }
}

/// Splits an output of `v` vertices × `c` channels × `batch` in layout `io` into one destination
/// per chunk of vertices, so chunks can be written in parallel whatever the layout.
pub(crate) fn chunk_outs<T>(
    out: &mut [T],
    io: Io,
    (batch, v, c): (usize, usize, usize),
) -> Vec<ChunkOut<'_, T>> {
    let n_chunks = v.div_ceil(CHUNK_ROWS);
    if batch * c == 0 {
        return (0..n_chunks).map(|_| ChunkOut::Discard).collect();
    }
    match io {
        Io::VertexChannel => {
            return out
                .chunks_mut(CHUNK_ROWS * batch * c)
                .map(ChunkOut::ChannelMajor)
                .collect();
        }
        Io::VertexBatch => {
            return out
                .chunks_mut(CHUNK_ROWS * batch * c)
                .map(|out| ChunkOut::VertexBatch { out, batch, c })
                .collect();
        }
        Io::BatchMajor => {}
    }
    let mut per_chunk: Vec<Vec<&mut [T]>> =
        (0..n_chunks).map(|_| Vec::with_capacity(batch)).collect();
    for slab in out.chunks_mut(v * c) {
        for (k, part) in slab.chunks_mut(CHUNK_ROWS * c).enumerate() {
            per_chunk[k].push(part);
        }
    }
    per_chunk.into_iter().map(ChunkOut::BatchMajor).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::random_vec;

    #[test]
    fn every_layout_converts_to_the_same_channel_major_array() {
        let (batch, v, c) = (5usize, 70usize, 3usize);
        let bvc = random_vec(batch * v * c, 1);
        let at = |b: usize, i: usize, ch: usize| bvc[(b * v + i) * c + ch];
        let mut vbc = vec![0.0; bvc.len()];
        let mut vcb = vec![0.0; bvc.len()];
        for b in 0..batch {
            for i in 0..v {
                for ch in 0..c {
                    vbc[(i * batch + b) * c + ch] = at(b, i, ch);
                    vcb[(i * c + ch) * batch + b] = at(b, i, ch);
                }
            }
        }
        let dims = (batch, v, c);
        assert_eq!(
            to_channel_major(
                &bvc,
                Io::BatchMajor,
                dims,
                &crate::workspace::Workspace::new()
            ),
            vcb
        );
        assert_eq!(
            to_channel_major(
                &vbc,
                Io::VertexBatch,
                dims,
                &crate::workspace::Workspace::new()
            ),
            vcb
        );
        assert_eq!(
            to_channel_major(
                &vcb,
                Io::VertexChannel,
                dims,
                &crate::workspace::Workspace::new()
            ),
            vcb
        );
        // A chunk of [V, B, C] blocks, and a gathered row, come out channel-major.
        let blocks = Blocks::new(&vbc, Io::VertexBatch, batch, c);
        let mut buf = vec![0.0; 4 * batch * c];
        assert_eq!(blocks.chunk(3, 4, &mut buf), &vcb[3 * 15..7 * 15]);
        let (mut tmp, mut acc) = (vec![0.0; 15], vec![0.0; 15]);
        blocks.gather::<crate::kernel::Plain>(&[2, 9], &[0.5, -2.0], &mut tmp, &mut acc);
        for k in 0..15 {
            let want = 0.5 * vcb[2 * 15 + k] - 2.0 * vcb[9 * 15 + k];
            assert!((acc[k] - want).abs() < 1e-15);
        }
    }
}

//! The start-up check of the int8 kernel on the model the board runs (at boot and, in the
//! deployable build, on every uploaded model before it is switched to).

use magic_core::model_file::Model;
use magic_core::nn::{self, Layer, Weights};
use magic_core::quant;

/// Checks the int8 kernel this build uses (the blocked `SMLAD` matrix-vector product, assembly)
/// against the portable one (the same lane arithmetic in plain Rust, which the host tests hold to
/// the plain dot product) on every row of every int8 layer of the model, with deterministic
/// pseudo-random activations.
pub fn self_check(model: &Model<'_>) -> Result<(), &'static str> {
    let mut seed = 0x2545_F491u32;
    for layer in model.encoder.iter().chain(model.decoder.iter()) {
        check_layer(layer, &mut seed)?;
    }
    Ok(())
}

fn check_layer(layer: &Layer<'_>, seed: &mut u32) -> Result<(), &'static str> {
    let Weights::Int8 { w, .. } = layer.weights else {
        return Ok(());
    };
    let (rows, cols) = (layer.rows as usize, layer.cols as usize);
    let mut x = [0i8; nn::MAX_WIDTH];
    let mut xp = [0u32; quant::packed_words(nn::MAX_WIDTH)];
    let Some(x) = x.get_mut(..cols) else {
        return Err("layer wider than MAX_WIDTH");
    };
    for v in x.iter_mut() {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 17;
        *seed ^= *seed << 5;
        *v = ((*seed >> 24) as u8 as i8).max(-127);
    }
    quant::pack_i8_pairs(x, &mut xp);
    let xp = xp.get(..quant::packed_words(cols)).unwrap_or(&[]);
    // Block by block (four rows, `4 · cols` contiguous bytes in the blocked layout; the last
    // block may be shorter): a block is itself a blocked matrix.
    for (b, block) in w.chunks(4 * cols.max(1)).enumerate() {
        let n = rows.saturating_sub(4 * b).min(4);
        let (mut fast, mut portable) = ([0i32; 4], [0i32; 4]);
        quant::matvec_i8_packed(block, n, cols, xp, &mut fast);
        quant::matvec_i8_packed_portable(block, n, cols, xp, &mut portable);
        if fast != portable {
            return Err("the DSP int8 kernel differs from the portable one");
        }
    }
    Ok(())
}

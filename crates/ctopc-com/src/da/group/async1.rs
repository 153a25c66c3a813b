//! IOPCAsyncIO (DA 1.0a): Read, Write, Refresh and Cancel over the engine's transactions,
//! the ones IOPCAsyncIO2/3 use; only the completion's route differs (`dataobject.rs`).
//!
//! The DA 1.0a transaction ID the client gets (`pTransactionID`) is the engine's cancel
//! ID of the transaction (0 when no item was valid: nothing is sent). `dwConnection`
//! names the IDataObject advise connection that receives the completion: a data-format
//! one (`OPCSTMFORMATDATA[TIME]`) for Read and Refresh, the `OPCSTMFORMATWRITECOMPLETE`
//! one for Write; any other is CONNECT_E_NOCONNECTION (as no advise at all is). The other
//! codes are IOPCAsyncIO2's: E_INVALIDARG for a zero count, NULL arrays or out-pointers
//! and an unknown OPCDATASOURCE, per-item OPC_E_INVALIDHANDLE / OPC_E_BADRIGHTS /
//! conversion errors with S_FALSE, E_FAIL for a Refresh of an inactive group and a Cancel
//! of an unknown or already delivered transaction.

use super::dataobject::Kind;
use super::io::{cancel_out, data_source, errors_out, value_items, PreErrors};
use super::Group_Impl;
use crate::com::abi::{self, in_array, write_out, ComResult, OutArray};
use crate::com::error;
use crate::com::interfaces::*;
use ctopc_core::model::AsyncStarted;
use ctopc_core::OpcError;
use windows::core::HRESULT;
use windows::Win32::System::Ole::CONNECT_E_NOCONNECTION;
use windows::Win32::System::Variant::VARIANT;

impl Group_Impl {
    /// The connection `connection` if it receives data streams (`data`) or write streams.
    fn da10_connection(&self, connection: u32, data: bool) -> ComResult<()> {
        match self.da10.connection_kind(connection) {
            Some(Kind::Data(_)) if data => Ok(()),
            Some(Kind::Write) if !data => Ok(()),
            _ => Err(CONNECT_E_NOCONNECTION.into()),
        }
    }

    /// One engine call starting a transaction, recorded for `connection` under the same
    /// engine lock (so before its completion can be dispatched).
    fn da10_start(
        &self,
        connection: u32,
        call: impl FnOnce(
            &mut ctopc_core::model::Engine,
            ctopc_core::Timestamp,
        ) -> Result<AsyncStarted, OpcError>,
    ) -> Result<AsyncStarted, OpcError> {
        self.ctx.runtime.with_engine(|e, now| {
            let started = call(e, now)?;
            self.da10.start_txn(started.cancel_id, connection);
            Ok(started)
        })
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn da10_read(
        &self,
        connection: u32,
        source: OPCDATASOURCE,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_transaction: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_transaction, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_transaction)?;
        let source = data_source(source)?;
        let handles = in_array(ph_server, count)?;
        self.da10_connection(connection, true)?;
        let started = self.da10_start(connection, |e, now| {
            e.async_read_source(now, self.handle, 0, source, handles)
        });
        // SAFETY: p_transaction was checked non-null by cancel_out above.
        unsafe { self.da10_out(started, p_transaction, pp_errors) }
    }

    /// # Safety
    /// The pointers are the COM method's parameters, valid as its IDL says (checked here).
    unsafe fn da10_write(
        &self,
        connection: u32,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        p_transaction: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> ComResult<HRESULT> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((p_transaction, pp_errors)) };
        let pp_errors = OutArray::new(pp_errors)?;
        cancel_out(p_transaction)?;
        let handles = in_array(ph_server, count)?;
        let values = in_array(p_values, count)?;
        self.da10_connection(connection, false)?;
        let mut pre = PreErrors::default();
        let items = value_items(handles, values, &mut pre);
        self.tell_caller();
        let started = self
            .da10_start(connection, |e, now| {
                e.async_write_vqt(now, self.handle, 0, &items)
            })
            .map(|mut s| {
                pre.apply(&mut s.results);
                s
            });
        // SAFETY: p_transaction was checked non-null by cancel_out above.
        unsafe { self.da10_out(started, p_transaction, pp_errors) }
    }

    /// # Safety
    /// `p_transaction` was checked non-null and zeroed by `cancel_out`.
    unsafe fn da10_out(
        &self,
        started: Result<AsyncStarted, OpcError>,
        p_transaction: *mut u32,
        pp_errors: OutArray<HRESULT>,
    ) -> ComResult<HRESULT> {
        let started = started.map_err(error::to_com)?;
        let hr = errors_out(pp_errors, &started.results)?;
        // SAFETY: checked non-null by the caller before the engine call.
        unsafe { p_transaction.write(started.cancel_id) };
        Ok(hr)
    }
}

impl IOPCAsyncIO_Impl for Group_Impl {
    unsafe fn Read(
        &self,
        connection: u32,
        source: OPCDATASOURCE,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_transaction: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        abi::hresult(self.da10_read(
            connection,
            source,
            count,
            ph_server,
            p_transaction,
            pp_errors,
        ))
    }

    unsafe fn Write(
        &self,
        connection: u32,
        count: u32,
        ph_server: *const OPCHANDLE,
        p_values: *const VARIANT,
        p_transaction: *mut u32,
        pp_errors: *mut *mut HRESULT,
    ) -> HRESULT {
        abi::hresult(self.da10_write(
            connection,
            count,
            ph_server,
            p_values,
            p_transaction,
            pp_errors,
        ))
    }

    unsafe fn Refresh(
        &self,
        connection: u32,
        source: OPCDATASOURCE,
        p_transaction: *mut u32,
    ) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((p_transaction,)) };
        cancel_out(p_transaction)?;
        let source = data_source(source)?;
        self.da10_connection(connection, true)?;
        let id = self
            .ctx
            .runtime
            .with_engine(|e, now| {
                let id = e.refresh2(now, self.handle, source, 0)?;
                self.da10.start_txn(id, connection);
                Ok(id)
            })
            .map_err(error::to_com)?;
        write_out(p_transaction, id)
    }

    unsafe fn Cancel(&self, transaction: u32) -> windows::core::Result<()> {
        if !self.da10.has_txn(transaction) {
            return Err(error::to_com(OpcError::Fail));
        }
        self.ctx
            .runtime
            .with_engine(|e, _| e.cancel2(self.handle, transaction))
            .map_err(error::to_com)
    }
}
